#include "decoder.hpp"

#include <cmath>
#include <numbers>

#include "timing.hpp"

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
std::uint32_t raw_at_least(double metres) {
  if (metres <= 0) return 0;
  return static_cast<std::uint32_t>(std::ceil(metres / kDistanceUnitM - 1e-9));
}

}  // namespace

ScalarDecoder::ScalarDecoder(const Calibration& calibration, const DecoderConfig& config)
    : config_(config),
      min_range_raw_(raw_at_least(config.min_range_m)),
      // Largest raw value <= max_range: one below the smallest raw value above it.
      max_range_raw_(raw_at_least(config.max_range_m + kDistanceUnitM) - 1) {
  for (int c = 0; c < kChannels; ++c) {
    const double elevation = calibration.elevation_deg[c] * kDegToRad;
    channels_[c] = {std::cos(elevation), std::sin(elevation), calibration.azimuth_offset_deg[c],
                    kChannelFiringOffsetNs[c] / 1000.0};
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
  if (raw < min_range_raw_) {
    filtered.add(FilterReason::kBelowMinRange);
    return false;
  }
  if (raw > max_range_raw_) {
    filtered.add(FilterReason::kAboveMaxRange);
    return false;
  }
  return true;
}

Point ScalarDecoder::make_point(const PacketView& packet, int block, int channel,
                                std::int64_t t0_ns, ReturnType type) const noexcept {
  const Channel& ch = channels_[channel];
  double azimuth_deg = packet.azimuth_cdeg(block) / 100.0 + ch.azimuth_offset_deg;
  if (config_.firing_time_correction) {
    // The laser fired Δt before the block's reference angle was sampled: rotate it back.
    azimuth_deg -= packet.motor_rpm() * 6e-6 * ch.firing_offset_us;
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
  p.azimuth_cdeg = static_cast<std::uint16_t>(std::lround(azimuth_deg * 100.0) % 36000);
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
    // Smallest raw difference that is NOT "too close" (0.1 m -> 25, i.e. 0.096 m is too close).
    const auto threshold_raw = raw_at_least(config_.dual_return_distance_threshold_m);
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
