// CLOCK_MONOTONIC in nanoseconds, for every deadline, pace and rate in the daemon: it does not
// jump when the host's wall clock is set (NTP, GPS time), so rotation, pacing and the
// per-second health tick are undisturbed by it. Both calls go through the vDSO (no syscall).
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

}  // namespace pandarcap
