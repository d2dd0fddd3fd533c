// ModelDecoder<Model>: one validated payload of a model -> points, the decoder the stream decoder
// holds for its model. The Pandar40P's is its tuned PacketDecoder (the scalar reference or a SIMD
// kernel: decoder.hpp, simd_decoder.hpp), unchanged. Every other model gets the generic scalar
// decoder below, written from the model's accessors alone (core/sensors/sensor_models.hpp), so a
// new model needs no decoder of its own.
//
// Per point, as for the 40P (decoder.hpp) and as tier4/nebula computes it:
//   r = raw distance × the packet's distance unit (its header's mm byte)
//   α = block azimuth + the channel's azimuth offset;  ω = the channel's elevation
//   x = r cos ω sin α,  y = r cos ω cos α,  z = r sin ω
//   time = t0 + Model::firing_offset_ns(block, channel, returns)
// Range: the configured limits within the model's own (nebula applies the sensor's: a QT128's
// 50 m, an XT's 0.05 m), compared in metres.
// Multiple returns (blocks k·n .. k·n+n-1 are one firing, n = returns per firing): the last block
// of a firing keeps its echo; an earlier one is dropped when it is byte-identical to another echo
// of the channel (dual_duplicate) or within dual_return_distance_threshold of one
// (dual_too_close), nebula's rule. In last+strongest (0x39) the kept echoes are labelled as the
// 40P's: last, strongest, last_strongest where the last one was dropped; other modes' echoes
// are labelled single.
// Firing-time correction is the 40P's alone (refused for other models at configuration).
// Never allocates; never fails on a valid packet.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <concepts>
#include <cstdint>
#include <numbers>
#include <span>
#include <utility>

#include "core/decode/calibration.hpp"
#include "core/decode/decoder.hpp"
#include "core/decode/decoder_target.hpp"
#include "core/decode/packet_decoder.hpp"
#include "core/frames/point.hpp"
#include "core/sensors/pandar40p.hpp"

namespace pandarcap {

template <class Model>
class ModelDecoder {
 public:
  static_assert(Model::kMaxPointsPerPacket <= kMaxPointsPerPacket);

  // Only the scalar decoder exists for this model: a SIMD `target` is not refused, and
  // target() says kScalar (the caller logs what was asked and what runs).
  ModelDecoder(const Calibration& calibration, const DecoderConfig& config, DecoderTarget)
      : config_(config),
        min_m_(std::max(config.min_range_m, Model::kMinRangeM)),
        max_m_(std::min(config.max_range_m, Model::kMaxRangeM)) {
    constexpr double kDegToRad = std::numbers::pi / 180.0;
    for (int c = 0; c < Model::kChannels; ++c) {
      const double elevation = calibration.elevation_deg[c] * kDegToRad;
      channels_[c] = {std::cos(elevation), std::sin(elevation), calibration.azimuth_offset_deg[c],
                      channel_azimuth_fixed(calibration.azimuth_offset_deg[c], 0, false)};
    }
  }

  DecodedPacket decode(std::span<const std::uint8_t> p, std::int64_t t0_ns,
                       std::span<Point, kMaxPointsPerPacket> out, FilterCounts& filtered) const {
    DecodedPacket result;
    const ReturnMode mode = Model::return_mode(p);
    const int returns = returns_per_firing(mode);
    const double unit_m = Model::distance_unit_m(p);
    const int rpm = std::min<int>(Model::motor_rpm(p), kMaxCorrectionRpm);
    std::uint16_t n = 0;
    for (int first = 0; first < Model::kBlocks; first += returns) {
      // keep[k][c]: echo k of channel c becomes a point. Decided for the whole firing first, so
      // each block's points are written together.
      std::array<std::array<bool, Model::kChannels>, 3> keep{};
      std::array<bool, Model::kChannels> merged{};  // 0x39: the last echo was dropped
      for (int c = 0; c < Model::kChannels; ++c) {
        std::array<std::uint16_t, 3> raw{};
        std::array<std::uint8_t, 3> refl{};
        for (int k = 0; k < returns; ++k) {
          raw[k] = Model::distance_raw(p, first + k, c);
          refl[k] = Model::reflectivity(p, first + k, c);
        }
        for (int k = 0; k < returns; ++k) {
          if (!in_range(raw[k], unit_m, filtered)) continue;
          if (k == returns - 1) {
            keep[k][c] = true;
            continue;
          }
          FilterReason dropped = FilterReason::kNoReturn;  // none
          for (int i = 0; i < returns; ++i) {
            if (i == k || raw[i] == 0) continue;
            if (raw[i] == raw[k] && refl[i] == refl[k]) {
              dropped = FilterReason::kDualDuplicate;
              break;
            }
            if (std::abs(raw[i] - raw[k]) * unit_m < config_.dual_return_distance_threshold_m) {
              dropped = FilterReason::kDualTooClose;
            }
          }
          if (dropped == FilterReason::kNoReturn) {
            keep[k][c] = true;
          } else {
            filtered.add(dropped);
            if (k == 0) merged[c] = true;
          }
        }
      }
      for (int k = 0; k < returns; ++k) {
        const int b = first + k;
        result.block_begin[b] = n;
        const std::uint16_t block_azimuth = Model::azimuth_cdeg(p, b);
        for (int c = 0; c < Model::kChannels; ++c) {
          if (!keep[k][c]) continue;
          out[n++] = make_point(p, b, c, returns, block_azimuth, unit_m, rpm, t0_ns,
                                label(mode, k, merged[c]));
        }
      }
    }
    result.block_begin[Model::kBlocks] = n;
    result.point_count = n;
    return result;
  }

  // As ScalarDecoder::relative_azimuth_bounds_cdeg (no firing-time correction here).
  std::pair<int, int> relative_azimuth_bounds_cdeg(int = 1500) const noexcept {
    double lo = channels_[0].azimuth_offset_deg, hi = lo;
    for (int c = 1; c < Model::kChannels; ++c) {
      lo = std::min(lo, channels_[c].azimuth_offset_deg);
      hi = std::max(hi, channels_[c].azimuth_offset_deg);
    }
    return {static_cast<int>(std::floor(lo * 100)) - 1, static_cast<int>(std::ceil(hi * 100)) + 1};
  }
  DecoderTarget target() const noexcept { return DecoderTarget::kScalar; }
  const DecoderConfig& config() const noexcept { return config_; }

 private:
  struct Channel {
    double cos_elevation, sin_elevation, azimuth_offset_deg;
    ChannelAzimuthFixed label;
  };

  bool in_range(std::uint16_t raw, double unit_m, FilterCounts& filtered) const noexcept {
    if (raw == 0) {
      filtered.add(FilterReason::kNoReturn);
      return false;
    }
    // A hair of slack, so 0.3 m in 4 mm units (raw 75) is in range though 75 × 0.004 is not
    // exactly 0.3 in binary floating point.
    const double d = raw * unit_m;
    if (d < min_m_ - 1e-9) {
      filtered.add(FilterReason::kBelowMinRange);
      return false;
    }
    if (d > max_m_ + 1e-9) {
      filtered.add(FilterReason::kAboveMaxRange);
      return false;
    }
    return true;
  }

  static ReturnType label(ReturnMode mode, int k, bool merged) noexcept {
    if (mode != ReturnMode::kDual) return ReturnType::kSingle;
    if (k == 0) return ReturnType::kLast;
    return merged ? ReturnType::kLastStrongest : ReturnType::kStrongest;
  }

  Point make_point(std::span<const std::uint8_t> p, int b, int c, int returns,
                   std::uint16_t block_azimuth, double unit_m, int rpm, std::int64_t t0_ns,
                   ReturnType type) const noexcept {
    constexpr double kDegToRad = std::numbers::pi / 180.0;
    const Channel& ch = channels_[c];
    double azimuth_deg = std::fmod(block_azimuth / 100.0 + ch.azimuth_offset_deg, 360.0);
    if (azimuth_deg < 0) azimuth_deg += 360.0;
    const double azimuth = azimuth_deg * kDegToRad;
    const double r = Model::distance_raw(p, b, c) * unit_m;
    Point point;
    point.x = static_cast<float>(r * ch.cos_elevation * std::sin(azimuth));
    point.y = static_cast<float>(r * ch.cos_elevation * std::cos(azimuth));
    point.z = static_cast<float>(r * ch.sin_elevation);
    point.distance_m = static_cast<float>(r);
    point.timestamp_ns = t0_ns + Model::firing_offset_ns(p, b, c, returns);
    point.azimuth_cdeg = corrected_azimuth_cdeg(block_azimuth, ch.label, rpm);
    point.intensity = Model::reflectivity(p, b, c);
    point.channel = static_cast<std::uint8_t>(c);
    point.return_type = type;
    return point;
  }

  std::array<Channel, Model::kChannels> channels_{};
  DecoderConfig config_;
  double min_m_, max_m_;
};

// The Pandar40P: its tuned decoder, the bytes it gives unchanged.
template <>
class ModelDecoder<Pandar40P> {
 public:
  ModelDecoder(const Calibration& calibration, const DecoderConfig& config, DecoderTarget target)
      : decoder_(calibration, config, target) {}

  DecodedPacket decode(std::span<const std::uint8_t> p, std::int64_t t0_ns,
                       std::span<Point, kMaxPointsPerPacket> out, FilterCounts& filtered) const {
    return decoder_.decode(PacketView::assume_valid(p), t0_ns, out, filtered);
  }
  std::pair<int, int> relative_azimuth_bounds_cdeg(int max_rpm = 1500) const noexcept {
    return decoder_.scalar().relative_azimuth_bounds_cdeg(max_rpm);
  }
  DecoderTarget target() const noexcept { return decoder_.target(); }
  const ScalarDecoder& scalar() const noexcept { return decoder_.scalar(); }

 private:
  PacketDecoder decoder_;
};

}  // namespace pandarcap
