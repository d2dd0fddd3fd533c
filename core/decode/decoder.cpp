#include "core/decode/decoder.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "core/sensors/timing.hpp"

namespace pandarcap {

std::string_view to_string(ReturnType type) noexcept {
  switch (type) {
    case ReturnType::kSingle:
      return "single";
    case ReturnType::kLast:
      return "last";
    case ReturnType::kStrongest:
      return "strongest";
    case ReturnType::kLastStrongest:
      return "last_strongest";
  }
  return "unknown";
}

std::string_view to_string(FilterReason reason) noexcept {
  switch (reason) {
    case FilterReason::kNoReturn:
      return "no_return";
    case FilterReason::kBelowMinRange:
      return "below_min_range";
    case FilterReason::kAboveMaxRange:
      return "above_max_range";
    case FilterReason::kDualDuplicate:
      return "dual_duplicate";
    case FilterReason::kDualTooClose:
      return "dual_too_close";
    case FilterReason::kOutlier:
      return "outlier";
    case FilterReason::kStanding:
      return "standing";
    case FilterReason::kReversed:
      return "reversed";
  }
  return "unknown";
}

std::uint64_t FilterCounts::total() const noexcept {
  std::uint64_t sum = 0;
  for (std::uint64_t n : by_reason)
    sum += n;
  return sum;
}

FilterCounts& FilterCounts::operator+=(const FilterCounts& other) noexcept {
  for (std::size_t i = 0; i < kFilterReasonCount; ++i)
    by_reason[i] += other.by_reason[i];
  return *this;
}

namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;

// Smallest raw distance (4 mm units) that is >= metres; a small epsilon keeps 0.3 m at raw 75
// although 0.3 / 0.004 is not exact in binary floating point.
// Results above any 16-bit distance saturate (config allows any max_range).
std::uint32_t raw_at_least(double metres) {
  if (!(metres > 0)) return 0;
  const double raw = std::ceil(metres / kDistanceUnitM - 1e-9);
  return raw >= 1e6 ? 1'000'000u : static_cast<std::uint32_t>(raw);
}

}  // namespace

RangeLimitsRaw range_limits_raw(const DecoderConfig& config) noexcept {
  RangeLimitsRaw limits;
  limits.min = raw_at_least(config.min_range_m);
  // Largest raw value <= max_range: one below the smallest raw value above it.
  limits.max = raw_at_least(config.max_range_m + kDistanceUnitM) - 1;
  // Smallest raw difference that is NOT "too close" (0.1 m -> 25, i.e. 0.096 m is too close).
  limits.dual_threshold = raw_at_least(config.dual_return_distance_threshold_m);
  return limits;
}

ChannelAzimuthFixed channel_azimuth_fixed(double offset_deg, std::int32_t firing_offset_ns,
                                          bool firing_time_correction) noexcept {
  ChannelAzimuthFixed fixed;
  double offset = std::fmod(offset_deg, 360.0);
  if (offset < 0) offset += 360.0;
  fixed.offset_q = static_cast<std::int32_t>(std::lround(offset * 100.0 * kAzimuthQ));
  if (fixed.offset_q >= kFullCircleQ) fixed.offset_q -= kFullCircleQ;
  if (firing_time_correction) {
    // δ = RPM x 6e-6 °/(RPM µs) x Δt: per RPM, 6e-7 x Δt[ns] hundredths of a degree.
    fixed.rpm_gain =
        static_cast<std::int32_t>(std::lround(firing_offset_ns * 6e-7 * kAzimuthQ * 256));
  }
  return fixed;
}

ScalarDecoder::ScalarDecoder(const Calibration& calibration, const DecoderConfig& config)
    : config_(config), limits_(range_limits_raw(config)) {
  for (int c = 0; c < kChannels; ++c) {
    const double elevation = calibration.elevation_deg[c] * kDegToRad;
    channels_[c] = {
        std::cos(elevation), std::sin(elevation), calibration.azimuth_offset_deg[c],
        kChannelFiringOffsetNs[c] / 1000.0,
        channel_azimuth_fixed(calibration.azimuth_offset_deg[c], kChannelFiringOffsetNs[c],
                              config.firing_time_correction)};
  }
}

std::pair<int, int> ScalarDecoder::relative_azimuth_bounds_cdeg(int max_rpm) const noexcept {
  double lo = 0, hi = 0;
  for (int c = 0; c < kChannels; ++c) {
    double rel = channels_[c].azimuth_offset_deg;
    double rel_min = rel;
    if (config_.firing_time_correction) rel_min -= max_rpm * 6e-6 * channels_[c].firing_offset_us;
    lo = c == 0 ? rel_min : std::min(lo, rel_min);
    hi = c == 0 ? rel : std::max(hi, rel);
  }
  return {static_cast<int>(std::floor(lo * 100)) - 1, static_cast<int>(std::ceil(hi * 100)) + 1};
}

bool ScalarDecoder::in_range(std::uint16_t raw, FilterCounts& filtered) const noexcept {
  if (raw == 0) {
    filtered.add(FilterReason::kNoReturn);
    return false;
  }
  if (raw < limits_.min) {
    filtered.add(FilterReason::kBelowMinRange);
    return false;
  }
  if (raw > limits_.max) {
    filtered.add(FilterReason::kAboveMaxRange);
    return false;
  }
  return true;
}

Point ScalarDecoder::make_point(const PacketView& packet, int block, int channel,
                                std::int64_t t0_ns, ReturnType type) const noexcept {
  const Channel& ch = channels_[channel];
  const int rpm = std::min<int>(packet.motor_rpm(), kMaxCorrectionRpm);
  double azimuth_deg = packet.azimuth_cdeg(block) / 100.0 + ch.azimuth_offset_deg;
  if (config_.firing_time_correction) {
    // The laser fired Δt before the block's reference angle was sampled: rotate it back.
    azimuth_deg -= rpm * 6e-6 * ch.firing_offset_us;
  }
  azimuth_deg = std::fmod(azimuth_deg, 360.0);
  if (azimuth_deg < 0) azimuth_deg += 360.0;
  const double azimuth = azimuth_deg * kDegToRad;
  const double r = packet.distance_raw(block, channel) * kDistanceUnitM;

  Point p;
  p.x = static_cast<float>(r * ch.cos_elevation * std::sin(azimuth));
  p.y = static_cast<float>(r * ch.cos_elevation * std::cos(azimuth));
  p.z = static_cast<float>(r * ch.sin_elevation);
  p.distance_m = static_cast<float>(r);
  p.timestamp_ns =
      t0_ns + block_offset_ns(block, packet.return_mode()) - kChannelFiringOffsetNs[channel];
  p.azimuth_cdeg = corrected_azimuth_cdeg(packet.azimuth_cdeg(block), ch.label, rpm);
  p.intensity = packet.reflectivity(block, channel);
  p.channel = static_cast<std::uint8_t>(channel);
  p.return_type = type;
  return p;
}

DecodedPacket ScalarDecoder::decode(const PacketView& packet, std::int64_t t0_ns,
                                    std::span<Point, kMaxPointsPerPacket> out,
                                    FilterCounts& filtered) const {
  DecodedPacket result;
  std::uint16_t n = 0;
  if (packet.return_mode() != ReturnMode::kDual) {
    for (int b = 0; b < kBlocks; ++b) {
      result.block_begin[b] = n;
      for (int c = 0; c < kChannels; ++c) {
        if (in_range(packet.distance_raw(b, c), filtered)) {
          out[n++] = make_point(packet, b, c, t0_ns, ReturnType::kSingle);
        }
      }
    }
  } else {
    const std::uint32_t threshold_raw = limits_.dual_threshold;
    for (int b = 0; b < kBlocks; b += 2) {
      // Decide per channel first, so the even block's points are written before the odd's.
      std::array<ReturnType, kChannels> strongest_type{};
      std::array<bool, kChannels> keep_last{}, keep_strongest{};
      for (int c = 0; c < kChannels; ++c) {
        const std::uint16_t d_last = packet.distance_raw(b, c);
        const std::uint16_t d_strongest = packet.distance_raw(b + 1, c);
        keep_last[c] = in_range(d_last, filtered);
        keep_strongest[c] = in_range(d_strongest, filtered);
        strongest_type[c] = ReturnType::kStrongest;
        if (keep_last[c] && keep_strongest[c]) {
          const bool identical =
              d_last == d_strongest && packet.reflectivity(b, c) == packet.reflectivity(b + 1, c);
          const auto diff = static_cast<std::uint32_t>(std::abs(d_last - d_strongest));
          if (identical || diff < threshold_raw) {
            filtered.add(identical ? FilterReason::kDualDuplicate : FilterReason::kDualTooClose);
            keep_last[c] = false;
            strongest_type[c] = ReturnType::kLastStrongest;
          }
        }
      }
      result.block_begin[b] = n;
      for (int c = 0; c < kChannels; ++c) {
        if (keep_last[c]) out[n++] = make_point(packet, b, c, t0_ns, ReturnType::kLast);
      }
      result.block_begin[b + 1] = n;
      for (int c = 0; c < kChannels; ++c) {
        if (keep_strongest[c]) out[n++] = make_point(packet, b + 1, c, t0_ns, strongest_type[c]);
      }
    }
  }
  result.block_begin[kBlocks] = n;
  result.point_count = n;
  return result;
}

}  // namespace pandarcap
