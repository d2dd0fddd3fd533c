// Time units, spelt once: every clock in pandarcap is an integer count of nanoseconds
// (CLOCK_REALTIME / CLOCK_MONOTONIC, pcap and packet times alike).
#pragma once

#include <cstdint>

namespace pandarcap {

inline constexpr std::int64_t kNsPerSecond = 1'000'000'000;
inline constexpr std::int64_t kNsPerMillisecond = 1'000'000;
inline constexpr std::int64_t kNsPerMicrosecond = 1'000;

}  // namespace pandarcap
