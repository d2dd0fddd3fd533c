// Firing times inside a packet (spec §2, MAN40P Appendix II).
//
// The packet time t0 is taken after the last block. Firing rounds are 55.56 µs apart and the last
// one ends 28.58 µs before t0. In dual-return mode both blocks of a pair share one round.
// Inside a round, channel c fires kChannelFiringOffsetNs[c] before the round ends:
//
//   point time = t0 + block_offset_ns(b, mode) - kChannelFiringOffsetNs[c]
//
// Example: single return, block 0, channel 8 (index 7): t0 - 528.62 µs - 54.67 µs.
#pragma once

#include <array>
#include <cstdint>

#include "core/sensors/packet.hpp"

namespace pandarcap {

inline constexpr std::int64_t kRoundPeriodNs = 55'560;   // one firing round
inline constexpr std::int64_t kLastRoundEndNs = 28'580;  // last round ends this long before t0

// Block end relative to t0 (negative: earlier). b is 0-based.
constexpr std::int64_t block_offset_ns(int b, ReturnMode mode) noexcept {
  const int rounds_after =
      mode == ReturnMode::kDual ? (kBlocks / 2 - 1) - b / 2 : (kBlocks - 1) - b;
  return -kLastRoundEndNs - kRoundPeriodNs * rounds_after;
}

// Δt of each channel (0-based index = manual channel - 1), ns before its block end.
inline constexpr std::array<std::int32_t, kChannels> kChannelFiringOffsetNs = {
    42220, 28470, 16040, 3620,  45490, 31740, 47460, 54670, 20620, 33710,  //  1..10
    40910, 8190,  20620, 27160, 50730, 8190,  14740, 36980, 45490, 52700,  // 11..20
    23890, 31740, 38950, 11470, 18650, 25190, 48760, 6230,  12770, 35010,  // 21..30
    21920, 9500,  43520, 29770, 17350, 4920,  42220, 28470, 16040, 3620,   // 31..40
};

// Firing rounds per packet and the packet period at the sensor's time-based trigger.
constexpr int rounds_per_packet(ReturnMode mode) noexcept {
  return kBlocks / returns_per_firing(mode);
}
constexpr std::int64_t packet_period_ns(ReturnMode mode) noexcept {
  return kRoundPeriodNs * rounds_per_packet(mode);
}

}  // namespace pandarcap
