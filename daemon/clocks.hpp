// The daemon's clocks (and the benchmarks'), all read through the vDSO (no syscall).
//
// CLOCK_MONOTONIC for every deadline, pace and rate: it does not jump when the host's wall clock
// is set (NTP, GPS time), so rotation, pacing and the per-second health tick are undisturbed by
// it. CLOCK_REALTIME only where a time is compared with a kernel receive timestamp
// (SO_TIMESTAMPNS is wall-clock time) or written into a file.
#pragma once

#include <time.h>

#include <cstdint>

namespace pandarcap {

inline std::int64_t monotonic_ns() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec * 1'000'000'000LL + ts.tv_nsec;
}

// The same clock at tick resolution (1-4 ms), several times cheaper: for heartbeats and the
// once-a-second checks of the receive and decode loops, never for latency.
inline std::int64_t coarse_monotonic_ns() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC_COARSE, &ts);
  return ts.tv_sec * 1'000'000'000LL + ts.tv_nsec;
}

// CPU time the calling thread has used, in seconds: what the benchmarks measure cost with.
inline double thread_cpu_seconds() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + static_cast<double>(ts.tv_nsec) / 1e9;
}

inline std::int64_t realtime_ns() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return ts.tv_sec * 1'000'000'000LL + ts.tv_nsec;
}

}  // namespace pandarcap
