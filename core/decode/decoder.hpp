// Scalar reference decoder: one validated packet -> points (spec §1.5, §2, §4.1).
//
// Per point: r = raw distance x 4 mm, elevation ω and azimuth offset from the calibration,
//   α = block azimuth + offset [- RPM x 6e-6 x Δt(channel) when firing-time correction is on]
//   x = r cos ω sin α,  y = r cos ω cos α,  z = r sin ω
//   time = t0 + block offset - Δt(channel)
// Worked example: channel 1 (index 0, nominal elevation 15°, offset -1.042°), block azimuth
// 9104 (91.04°), raw distance 2500 (10 m): α = 89.998°, point ≈ (9.659, 0.0003, 2.588) m.
//
// Filtering, counted by reason: raw distance 0 (no return), below min_range, above max_range.
// Dual return (0x39): blocks (2k, 2k+1) are one firing, even = last, odd = strongest. When both
// echoes of a channel survive the range filter and are byte-identical, or closer together than
// dual_return_distance_threshold, only the odd block's copy is kept, labelled kLastStrongest.
//
// This decoder is deliberately plain (double precision, std::sin/cos per point): it is the
// reference the SIMD decoder must match. It never allocates and never fails on a valid packet.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string_view>

#include "core/decode/calibration.hpp"
#include "core/frames/point.hpp"
#include "core/sensors/packet.hpp"

namespace pandarcap {

inline constexpr int kMaxPointsPerPacket = kBlocks * kChannels;  // 400

// Firing-time correction uses the tail's RPM clamped to this (the sensor spins at 600 or 1200;
// a corrupt RPM field must not turn a sub-degree correction into a large rotation).
inline constexpr int kMaxCorrectionRpm = 2400;

struct DecoderConfig {
  double min_range_m = 0.3;
  double max_range_m = 200.0;
  double dual_return_distance_threshold_m = 0.1;
  bool firing_time_correction = false;  // spec §2.4: <= 0.2° at 600 RPM
};

enum class FilterReason : std::uint8_t {
  kNoReturn,  // raw distance 0
  kBelowMinRange,
  kAboveMaxRange,
  kDualDuplicate,  // dual: identical to the strongest echo
  kDualTooClose,   // dual: within dual_return_distance_threshold of the strongest echo
  kOutlier,   // the packet was an isolated outlier in the rotation (core/decode/stream_decoder.hpp)
  kStanding,  // the motor did not turn: the packet's azimuth stood (core/decode/stream_decoder.hpp)
  kReversed,  // the stream's azimuth ran backwards (core/decode/stream_decoder.hpp)
};
inline constexpr std::size_t kFilterReasonCount = 8;
std::string_view to_string(FilterReason reason) noexcept;  // "no_return", ...

// The range filter and dual-return threshold in raw 4 mm units (inclusive limits).
struct RangeLimitsRaw {
  std::uint32_t min = 0, max = 0;
  std::uint32_t dual_threshold = 0;  // raw differences below this are "too close"
};
RangeLimitsRaw range_limits_raw(const DecoderConfig& config) noexcept;

// A point's azimuth label (Point::azimuth_cdeg, the angle frames are cut by) in fixed point:
// 1/1024 of 0.01°. Both decoders compute it with this integer arithmetic, so they agree on it
// exactly and therefore cut frames identically; the floating-point angle used for x and y is
// not rounded.
inline constexpr std::int32_t kAzimuthQ = 1024;
inline constexpr std::int32_t kFullCircleQ = 36000 * kAzimuthQ;

struct ChannelAzimuthFixed {
  std::int32_t offset_q = 0;  // calibration azimuth offset, normalised into [0, kFullCircleQ)
  std::int32_t rpm_gain = 0;  // firing-time correction per RPM, in 1/256 of a step; 0 when off
};
ChannelAzimuthFixed channel_azimuth_fixed(double offset_deg, std::int32_t firing_offset_ns,
                                          bool firing_time_correction) noexcept;

// block_cdeg in 0..35999, rpm in 0..kMaxCorrectionRpm; returns 0..35999.
constexpr std::uint16_t corrected_azimuth_cdeg(std::uint16_t block_cdeg, ChannelAzimuthFixed ch,
                                               std::int32_t rpm) noexcept {
  std::int32_t q = block_cdeg * kAzimuthQ + ch.offset_q - ((rpm * ch.rpm_gain + 128) >> 8);
  if (q < 0) {
    q += kFullCircleQ;
  } else if (q >= kFullCircleQ) {
    q -= kFullCircleQ;
  }
  const std::int32_t cdeg = (q + kAzimuthQ / 2) / kAzimuthQ;
  return static_cast<std::uint16_t>(cdeg == 36000 ? 0 : cdeg);
}

struct FilterCounts {
  std::array<std::uint64_t, kFilterReasonCount> by_reason{};
  void add(FilterReason reason, std::uint64_t n = 1) noexcept {
    by_reason[static_cast<std::size_t>(reason)] += n;
  }
  std::uint64_t operator[](FilterReason reason) const noexcept {
    return by_reason[static_cast<std::size_t>(reason)];
  }
  std::uint64_t total() const noexcept;
  FilterCounts& operator+=(const FilterCounts& other) noexcept;
};

// Where a packet's points went: points of block b are out[block_begin[b] .. block_begin[b+1]).
struct DecodedPacket {
  std::uint16_t point_count = 0;
  std::array<std::uint16_t, kBlocks + 1> block_begin{};
};

class ScalarDecoder {
 public:
  ScalarDecoder(const Calibration& calibration, const DecoderConfig& config);

  // Decodes a validated packet whose absolute time is t0_ns. Adds filtered counts to `filtered`.
  DecodedPacket decode(const PacketView& packet, std::int64_t t0_ns,
                       std::span<Point, kMaxPointsPerPacket> out, FilterCounts& filtered) const;

  // Range of (corrected azimuth - block azimuth) over channels, in 0.01°, including the
  // firing-time correction at up to `max_rpm`. The frame assembler uses it to know when no
  // later point can still fall before the cut.
  std::pair<int, int> relative_azimuth_bounds_cdeg(int max_rpm = 1500) const noexcept;

  const DecoderConfig& config() const noexcept { return config_; }

 private:
  struct Channel {
    double cos_elevation, sin_elevation, azimuth_offset_deg;
    double firing_offset_us;
    ChannelAzimuthFixed label;
  };
  std::array<Channel, kChannels> channels_{};
  DecoderConfig config_;
  RangeLimitsRaw limits_;

  bool in_range(std::uint16_t raw, FilterCounts& filtered) const noexcept;
  Point make_point(const PacketView& packet, int block, int channel, std::int64_t t0_ns,
                   ReturnType type) const noexcept;
};

}  // namespace pandarcap
