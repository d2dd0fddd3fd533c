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

// A kernel receive timestamp (CLOCK_REALTIME) `received` on the monotonic clock, read at
// `now_mono` (and `now_real`): its age taken from `now`, bounded by how long ago the source was
// last found empty (`empty_mono`, plus `slack` for what the kernel held but had not yet handed
// over), since nothing that waited afterwards had arrived before: a wall clock stepped since
// the datagram arrived moves it no further than that.
inline std::int64_t arrival_on_monotonic(std::int64_t received, std::int64_t now_real,
                                         std::int64_t now_mono, std::int64_t empty_mono,
                                         std::int64_t slack) noexcept {
  const std::int64_t bound = now_mono - empty_mono + slack;
  const std::int64_t age = now_real - received;
  return now_mono - (age < 0 ? 0 : age > bound ? (bound < 0 ? 0 : bound) : age);
}

}  // namespace pandarcap
