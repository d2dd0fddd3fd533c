// SIMD packet decoder: the same points as ScalarDecoder, a block of 40 channels at a time.
//
// How it is fast (spec §4.1 geometry, rewritten so nothing transcendental runs per point):
//   x = r cos ω sin(A + o) = r (sin A · cos ω cos o + cos A · cos ω sin o)
//   y = r cos ω cos(A + o) = r (cos A · cos ω cos o − sin A · cos ω sin o)
//   z = r sin ω
// with A the block azimuth and o the channel's azimuth offset. cos ω cos o and cos ω sin o are
// per-channel constants (a few hundred floats, computed once), sin A / cos A are computed once per
// block from two small double-precision tables (angle addition, 10 KB), and each point is then two
// multiply-adds and three multiplies. With firing-time correction, o becomes o − δ(RPM, channel)
// and the per-channel constants are rotated by δ once per packet (δ < 0.8°, so a short Taylor
// series is exact to float precision).
//
// The 3-byte channel records are split into distance-low, distance-high and reflectivity vectors
// with interleaved loads (shuffles, no gathers). Range filters and the dual-return rules are lane
// masks, counted per reason with popcounts; kept channels are compacted in channel order and
// written into the caller's buffer, so the output is ordered exactly as the scalar decoder's.
//
// Agreement with the reference: the same points kept and filtered, the same channel, return type,
// intensity, timestamp and azimuth label (both decoders compute the label with the same integer
// arithmetic, see corrected_azimuth_cdeg), and x, y, z, distance within 1e-4 m (float arithmetic
// against the reference's double). tests/test_simd_decoder.cpp checks this for every target the
// machine supports.
#pragma once

#include <array>
#include <cstdint>
#include <span>

#include "core/decode/calibration.hpp"
#include "core/decode/decoder.hpp"
#include "core/decode/decoder_target.hpp"
#include "core/frames/point.hpp"
#include "core/sensors/packet.hpp"

namespace pandarcap {

// Per-channel constants and per-block angle tables the SIMD kernels read. Arrays are padded to
// kLanes (a multiple of the widest vector, 16 floats) with zeros, so kernels never need a tail
// loop.
struct alignas(64) SimdDecoderTables {
  static constexpr int kLanes = 48;
  static constexpr int kAngleFineSteps = 64;  // block azimuth = coarse * 64 + fine, in 0.01°
  static constexpr int kAngleCoarseSteps =
      (kAzimuthLimitCdeg + kAngleFineSteps - 1) / kAngleFineSteps;  // 563

  alignas(64) std::array<float, kLanes> a{};  // cos ω cos o
  alignas(64) std::array<float, kLanes> b{};  // cos ω sin o
  alignas(64) std::array<float, kLanes> sin_elevation{};
  alignas(64) std::array<float, kLanes> cos_elevation{};
  alignas(64) std::array<float, kLanes> cos_offset{};
  alignas(64) std::array<float, kLanes> sin_offset{};
  alignas(64) std::array<float, kLanes> correction_rad_per_rpm{};  // δ / RPM
  alignas(64) std::array<std::int32_t, kLanes> offset_q{};         // see ChannelAzimuthFixed
  alignas(64) std::array<std::int32_t, kLanes> label_offset{};     // offset_q + half a step
  alignas(64) std::array<std::int32_t, kLanes> rpm_gain{};
  alignas(64) std::array<std::int32_t, kLanes> channel_byte{};  // c << 24, the Point's channel
  alignas(64) std::array<std::int32_t, kLanes> firing_offset_ns{};
  // firing_offset_ns with the sign bit flipped: an unsigned compare done with signed lanes.
  alignas(64) std::array<std::int32_t, kLanes> firing_offset_biased{};
  // sin and cos of (coarse * 64) and of (fine) hundredths of a degree.
  std::array<std::array<double, 2>, kAngleCoarseSteps> coarse_sin_cos{};
  std::array<std::array<double, 2>, kAngleFineSteps> fine_sin_cos{};

  RangeLimitsRaw limits;
  bool firing_time_correction = false;

  SimdDecoderTables(const Calibration& calibration, const DecoderConfig& config);
};

// One target's kernel: decodes `packet` into out[0..400) like ScalarDecoder::decode.
using SimdKernel = DecodedPacket (*)(const SimdDecoderTables&, const PacketView&, std::int64_t,
                                     Point*, FilterCounts&);

// The kernel built for `target`, or nullptr when this binary has none (scalar, or another
// architecture). Does not check the CPU.
SimdKernel simd_decoder_kernel(DecoderTarget target) noexcept;

// Whether this CPU can run `target`'s kernel (false for scalar, and for targets not compiled in).
bool simd_target_supported(DecoderTarget target) noexcept;

}  // namespace pandarcap
