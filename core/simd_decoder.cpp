// The SIMD decoder's kernels, compiled once per instruction set by Google Highway
// (foreach_target re-includes this file for each target), and the table that picks one at run
// time. See simd_decoder.hpp for the arithmetic.
#include "core/simd_decoder.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numbers>
#include <stdexcept>
#include <string>

#include "core/timing.hpp"

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "core/simd_decoder.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

HWY_BEFORE_NAMESPACE();
namespace pandarcap {
namespace HWY_NAMESPACE {
namespace {

namespace hn = hwy::HWY_NAMESPACE;

constexpr int kLanes = SimdDecoderTables::kLanes;

// At most 16 float lanes (3 vectors per block) and 64 byte lanes (the record split), so the
// padded arrays are large enough on scalable targets (SVE) too.
using DF = hn::CappedTag<float, 16>;
using DI = hn::RebindToSigned<DF>;
using DU8 = hn::CappedTag<std::uint8_t, 64>;

// One block's 40 channel records split into planes; lanes 40..63 are zero.
struct BlockPlanes {
  alignas(64) std::uint8_t distance_low[64];
  alignas(64) std::uint8_t distance_high[64];
  alignas(64) std::uint8_t reflectivity[64];
};

// One block's points before compaction: every channel's fields, and which channels are kept.
struct BlockPoints {
  alignas(64) float xyzd[kLanes * 4];          // x, y, z, distance per channel
  alignas(64) std::uint32_t meta[kLanes * 2];  // Point bytes 24..31 per channel
  std::uint64_t kept = 0;                      // bit c: channel c is kept
};

// The channel constants a packet uses: the calibration's, or rotated by the firing-time
// correction at this packet's RPM.
struct ChannelConstants {
  const float* a;
  const float* b;
  const std::int32_t* offset_q;
};

struct FilterTally {
  std::size_t no_return = 0, below = 0, above = 0, duplicate = 0, too_close = 0;
};

HWY_INLINE void split_block(const std::uint8_t* block, BlockPlanes& planes) {
  alignas(64) std::uint8_t records[3 * 64] = {};
  std::memcpy(records, block + 4, 3 * kChannels);
  const DU8 d8;
  const std::size_t n = hn::Lanes(d8);
  for (std::size_t i = 0; i < static_cast<std::size_t>(kChannels); i += n) {
    hn::Vec<DU8> low, high, reflectivity;
    hn::LoadInterleaved3(d8, records + 3 * i, low, high, reflectivity);
    hn::Store(low, d8, planes.distance_low + i);
    hn::Store(high, d8, planes.distance_high + i);
    hn::Store(reflectivity, d8, planes.reflectivity + i);
  }
}

HWY_INLINE hn::Vec<DI> load_distance(const BlockPlanes& planes, std::size_t i) {
  const DI di;
  const hn::Rebind<std::uint8_t, DI> d8;
  const auto low = hn::PromoteTo(di, hn::Load(d8, planes.distance_low + i));
  const auto high = hn::PromoteTo(di, hn::Load(d8, planes.distance_high + i));
  return hn::Or(low, hn::ShiftLeft<8>(high));
}

HWY_INLINE hn::Vec<DI> load_reflectivity(const BlockPlanes& planes, std::size_t i) {
  const DI di;
  const hn::Rebind<std::uint8_t, DI> d8;
  return hn::PromoteTo(di, hn::Load(d8, planes.reflectivity + i));
}

// Lanes of real channels (the last vector of a 16-lane target covers channels 32..47).
HWY_INLINE hn::Mask<DI> real_channels(std::size_t i) {
  const DI di;
  return hn::Lt(hn::Iota(di, static_cast<std::int32_t>(i)), hn::Set(di, kChannels));
}

// The range filter on one vector of distances; counts each reason once per real channel.
HWY_INLINE hn::Mask<DI> in_range(const SimdDecoderTables& t, hn::Vec<DI> distance,
                                 hn::Mask<DI> real, FilterTally& tally) {
  const DI di;
  const auto zero = hn::And(hn::Eq(distance, hn::Zero(di)), real);
  const auto returned = hn::AndNot(zero, real);
  const auto below =
      hn::And(hn::Lt(distance, hn::Set(di, static_cast<std::int32_t>(t.limits.min))), returned);
  const auto above =
      hn::And(hn::Gt(distance, hn::Set(di, static_cast<std::int32_t>(t.limits.max))), returned);
  tally.no_return += hn::CountTrue(di, zero);
  tally.below += hn::CountTrue(di, below);
  tally.above += hn::CountTrue(di, above);
  return hn::AndNot(hn::Or(below, above), returned);
}

// Computes one vector of points (channels i..i+N) of a block and appends the kept channels.
HWY_INLINE void emit(const SimdDecoderTables& t, const ChannelConstants& k, std::size_t i,
                     std::uint16_t block_azimuth, float sin_azimuth, float cos_azimuth,
                     hn::Vec<DI> distance, hn::Vec<DI> reflectivity, hn::Vec<DI> return_type,
                     hn::Mask<DI> keep, BlockPoints& out) {
  const DF df;
  const DI di;

  const auto r =
      hn::Mul(hn::ConvertTo(df, distance), hn::Set(df, static_cast<float>(kDistanceUnitM)));
  const auto a = hn::Load(df, k.a + i);
  const auto b = hn::Load(df, k.b + i);
  const auto sin_a = hn::Set(df, sin_azimuth);
  const auto cos_a = hn::Set(df, cos_azimuth);
  // sin(A + o) cos ω and cos(A + o) cos ω by angle addition.
  const auto x_unit = hn::MulAdd(sin_a, a, hn::Mul(cos_a, b));
  const auto y_unit = hn::NegMulAdd(sin_a, b, hn::Mul(cos_a, a));
  const auto x = hn::Mul(r, x_unit);
  const auto y = hn::Mul(r, y_unit);
  const auto z = hn::Mul(r, hn::Load(df, t.sin_elevation.data() + i));
  hn::StoreInterleaved4(x, y, z, r, df, out.xyzd + 4 * i);

  // The azimuth label, exactly as corrected_azimuth_cdeg computes it.
  const auto full = hn::Set(di, kFullCircleQ);
  auto q = hn::Add(hn::Set(di, block_azimuth * kAzimuthQ), hn::Load(di, k.offset_q + i));
  q = hn::IfThenElse(hn::Lt(q, hn::Zero(di)), hn::Add(q, full), q);
  q = hn::IfThenElse(hn::Gt(q, hn::Set(di, kFullCircleQ - 1)), hn::Sub(q, full), q);
  auto cdeg = hn::ShiftRight<10>(hn::Add(q, hn::Set(di, kAzimuthQ / 2)));
  static_assert(kAzimuthQ == 1 << 10);
  cdeg = hn::IfThenZeroElse(hn::Eq(cdeg, hn::Set(di, 36000)), cdeg);

  // Bytes 24..31 of the Point: azimuth (u16), intensity, channel | return type, 3 reserved.
  const auto meta = hn::Or(hn::Or(cdeg, hn::ShiftLeft<16>(reflectivity)),
                           hn::Load(di, t.channel_byte.data() + i));
  const hn::RebindToUnsigned<DI> du;
  hn::StoreInterleaved2(hn::BitCast(du, meta), hn::BitCast(du, return_type), du, out.meta + 2 * i);

  // A bit mask rather than CompressStore: Highway 1.0.3's AVX2 compress copies a 1 KB index
  // table per call, and write_points walks the kept channels anyway.
  std::uint8_t bits[8] = {};
  hn::StoreMaskBits(di, keep, bits);
  std::uint64_t kept = 0;
  std::memcpy(&kept, bits, sizeof kept);
  out.kept |= kept << i;
}

// Writes the kept points of one block, in channel order, from out[n]; returns the new n.
HWY_INLINE std::size_t write_points(const SimdDecoderTables& t, const BlockPoints& block,
                                    std::int64_t block_time_ns, Point* out, std::size_t n) {
  static_assert(offsetof(Point, x) == 0 && offsetof(Point, distance_m) == 12);
  static_assert(offsetof(Point, timestamp_ns) == 16 && offsetof(Point, azimuth_cdeg) == 24);
  static_assert(offsetof(Point, intensity) == 26 && offsetof(Point, channel) == 27);
  static_assert(offsetof(Point, return_type) == 28);
  for (std::uint64_t kept = block.kept; kept != 0; kept &= kept - 1, ++n) {
    const auto c = static_cast<std::size_t>(__builtin_ctzll(kept));
    auto* bytes = reinterpret_cast<unsigned char*>(out + n);
    std::memcpy(bytes, block.xyzd + 4 * c, 16);
    const std::int64_t time = block_time_ns - t.firing_offset_ns[c];
    std::memcpy(bytes + 16, &time, 8);
    std::memcpy(bytes + 24, block.meta + 2 * c, 8);
  }
  return n;
}

ChannelConstants channel_constants(const SimdDecoderTables& t, int rpm, float* a, float* b,
                                   std::int32_t* offset_q) {
  if (!t.firing_time_correction) return {t.a.data(), t.b.data(), t.offset_q.data()};
  const DF df;
  const DI di;
  const auto vrpm = hn::Set(df, static_cast<float>(rpm));
  const auto vrpm_i = hn::Set(di, rpm);
  for (std::size_t i = 0; i < static_cast<std::size_t>(kLanes); i += hn::Lanes(df)) {
    // δ < 0.8° = 0.014 rad: the series' next terms are below 1e-17.
    const auto delta = hn::Mul(hn::Load(df, t.correction_rad_per_rpm.data() + i), vrpm);
    const auto d2 = hn::Mul(delta, delta);
    const auto cos_d = hn::MulAdd(d2, hn::MulAdd(d2, hn::Set(df, 1.0f / 24), hn::Set(df, -0.5f)),
                                  hn::Set(df, 1.0f));
    const auto sin_d = hn::Mul(
        delta, hn::MulAdd(d2, hn::MulAdd(d2, hn::Set(df, 1.0f / 120), hn::Set(df, -1.0f / 6)),
                          hn::Set(df, 1.0f)));
    const auto co = hn::Load(df, t.cos_offset.data() + i);
    const auto so = hn::Load(df, t.sin_offset.data() + i);
    const auto ce = hn::Load(df, t.cos_elevation.data() + i);
    // cos(o − δ) = cos o cos δ + sin o sin δ;  sin(o − δ) = sin o cos δ − cos o sin δ
    hn::Store(hn::Mul(ce, hn::MulAdd(co, cos_d, hn::Mul(so, sin_d))), df, a + i);
    hn::Store(hn::Mul(ce, hn::NegMulAdd(co, sin_d, hn::Mul(so, cos_d))), df, b + i);
    const auto gain = hn::Load(di, t.rpm_gain.data() + i);
    const auto correction = hn::ShiftRight<8>(hn::Add(hn::Mul(vrpm_i, gain), hn::Set(di, 128)));
    hn::Store(hn::Sub(hn::Load(di, t.offset_q.data() + i), correction), di, offset_q + i);
  }
  return {a, b, offset_q};
}

}  // namespace

DecodedPacket DecodeKernel(const SimdDecoderTables& t, const PacketView& packet, std::int64_t t0_ns,
                           Point* out, FilterCounts& filtered) {
  const DI di;
  const std::size_t lanes = hn::Lanes(di);
  const ReturnMode mode = packet.return_mode();
  const int rpm = std::min<int>(packet.motor_rpm(), kMaxCorrectionRpm);

  alignas(64) float rotated_a[kLanes];
  alignas(64) float rotated_b[kLanes];
  alignas(64) std::int32_t rotated_offset_q[kLanes];
  const ChannelConstants k = channel_constants(t, rpm, rotated_a, rotated_b, rotated_offset_q);

  // sin and cos of each block azimuth: coarse and fine table entries combined in double.
  float sin_azimuth[kBlocks], cos_azimuth[kBlocks];
  for (int b = 0; b < kBlocks; ++b) {
    const unsigned azimuth = packet.azimuth_cdeg(b);  // < 36000: validate() checked it
    const auto& coarse = t.coarse_sin_cos[azimuth / SimdDecoderTables::kAngleFineSteps];
    const auto& fine = t.fine_sin_cos[azimuth % SimdDecoderTables::kAngleFineSteps];
    sin_azimuth[b] = static_cast<float>(coarse[0] * fine[1] + coarse[1] * fine[0]);
    cos_azimuth[b] = static_cast<float>(coarse[1] * fine[1] - coarse[0] * fine[0]);
  }

  DecodedPacket result;
  FilterTally tally;
  std::size_t n = 0;
  BlockPlanes planes[2];
  BlockPoints points[2];

  if (mode != ReturnMode::kDual) {
    const auto single = hn::Set(di, static_cast<std::int32_t>(ReturnType::kSingle));
    for (int b = 0; b < kBlocks; ++b) {
      split_block(packet.block(b), planes[0]);
      points[0].kept = 0;
      const auto azimuth = packet.azimuth_cdeg(b);
      for (std::size_t i = 0; i < static_cast<std::size_t>(kChannels); i += lanes) {
        const auto distance = load_distance(planes[0], i);
        const auto keep = in_range(t, distance, real_channels(i), tally);
        emit(t, k, i, azimuth, sin_azimuth[b], cos_azimuth[b], distance,
             load_reflectivity(planes[0], i), single, keep, points[0]);
      }
      result.block_begin[b] = static_cast<std::uint16_t>(n);
      n = write_points(t, points[0], t0_ns + block_offset_ns(b, mode), out, n);
    }
  } else {
    const auto last = hn::Set(di, static_cast<std::int32_t>(ReturnType::kLast));
    const auto strongest = hn::Set(di, static_cast<std::int32_t>(ReturnType::kStrongest));
    const auto merged_type = hn::Set(di, static_cast<std::int32_t>(ReturnType::kLastStrongest));
    const auto threshold = hn::Set(di, static_cast<std::int32_t>(t.limits.dual_threshold));
    for (int b = 0; b < kBlocks; b += 2) {
      split_block(packet.block(b), planes[0]);
      split_block(packet.block(b + 1), planes[1]);
      points[0].kept = points[1].kept = 0;
      for (std::size_t i = 0; i < static_cast<std::size_t>(kChannels); i += lanes) {
        const auto real = real_channels(i);
        const auto d_last = load_distance(planes[0], i);
        const auto d_strongest = load_distance(planes[1], i);
        const auto r_last = load_reflectivity(planes[0], i);
        const auto r_strongest = load_reflectivity(planes[1], i);
        auto keep_last = in_range(t, d_last, real, tally);
        const auto keep_strongest = in_range(t, d_strongest, real, tally);
        // Both echoes kept: identical, or closer than the threshold, keeps only the odd block's.
        const auto both = hn::And(keep_last, keep_strongest);
        const auto identical =
            hn::And(both, hn::And(hn::Eq(d_last, d_strongest), hn::Eq(r_last, r_strongest)));
        const auto close = hn::And(hn::AndNot(identical, both),
                                   hn::Lt(hn::Abs(hn::Sub(d_last, d_strongest)), threshold));
        const auto merged = hn::Or(identical, close);
        tally.duplicate += hn::CountTrue(di, identical);
        tally.too_close += hn::CountTrue(di, close);
        keep_last = hn::AndNot(merged, keep_last);
        emit(t, k, i, packet.azimuth_cdeg(b), sin_azimuth[b], cos_azimuth[b], d_last, r_last, last,
             keep_last, points[0]);
        emit(t, k, i, packet.azimuth_cdeg(b + 1), sin_azimuth[b + 1], cos_azimuth[b + 1],
             d_strongest, r_strongest, hn::IfThenElse(merged, merged_type, strongest),
             keep_strongest, points[1]);
      }
      const std::int64_t time = t0_ns + block_offset_ns(b, mode);  // one firing for both
      result.block_begin[b] = static_cast<std::uint16_t>(n);
      n = write_points(t, points[0], time, out, n);
      result.block_begin[b + 1] = static_cast<std::uint16_t>(n);
      n = write_points(t, points[1], time, out, n);
    }
  }
  result.block_begin[kBlocks] = static_cast<std::uint16_t>(n);
  result.point_count = static_cast<std::uint16_t>(n);
  filtered.add(FilterReason::kNoReturn, tally.no_return);
  filtered.add(FilterReason::kBelowMinRange, tally.below);
  filtered.add(FilterReason::kAboveMaxRange, tally.above);
  filtered.add(FilterReason::kDualDuplicate, tally.duplicate);
  filtered.add(FilterReason::kDualTooClose, tally.too_close);
  return result;
}

}  // namespace HWY_NAMESPACE
}  // namespace pandarcap
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace pandarcap {
namespace {

struct KernelEntry {
  DecoderTarget target;
  std::int64_t hwy_target;
  SimdKernel kernel;
};

// Every kernel this binary holds. Highway compiles the targets HWY_TARGETS names (on x86-64:
// SSE4, AVX2 and AVX-512 beside the baseline); a target missing here is simply not offered.
constexpr KernelEntry kKernels[] = {
#if HWY_TARGETS & HWY_SSE4
    {DecoderTarget::kSse4, HWY_SSE4, &N_SSE4::DecodeKernel},
#endif
#if HWY_TARGETS & HWY_AVX2
    {DecoderTarget::kAvx2, HWY_AVX2, &N_AVX2::DecodeKernel},
#endif
#if HWY_TARGETS & HWY_AVX3
    {DecoderTarget::kAvx512, HWY_AVX3, &N_AVX3::DecodeKernel},
#endif
#if HWY_TARGETS & HWY_NEON
    {DecoderTarget::kNeon, HWY_NEON, &N_NEON::DecodeKernel},
#endif
#if HWY_TARGETS & HWY_SVE
    {DecoderTarget::kSve, HWY_SVE, &N_SVE::DecodeKernel},
#endif
#if HWY_TARGETS & HWY_SVE2
    {DecoderTarget::kSve2, HWY_SVE2, &N_SVE2::DecodeKernel},
#endif
};

const KernelEntry* find_kernel(DecoderTarget target) noexcept {
  for (const KernelEntry& entry : kKernels) {
    if (entry.target == target) return &entry;
  }
  return nullptr;
}

constexpr double kCdegToRad = std::numbers::pi / 18000.0;

}  // namespace

SimdDecoderTables::SimdDecoderTables(const Calibration& calibration, const DecoderConfig& config)
    : limits(range_limits_raw(config)), firing_time_correction(config.firing_time_correction) {
  constexpr double kDegToRad = std::numbers::pi / 180.0;
  for (int c = 0; c < kChannels; ++c) {
    const double elevation = calibration.elevation_deg[c] * kDegToRad;
    const double offset = calibration.azimuth_offset_deg[c] * kDegToRad;
    cos_elevation[c] = static_cast<float>(std::cos(elevation));
    sin_elevation[c] = static_cast<float>(std::sin(elevation));
    cos_offset[c] = static_cast<float>(std::cos(offset));
    sin_offset[c] = static_cast<float>(std::sin(offset));
    a[c] = static_cast<float>(std::cos(elevation) * std::cos(offset));
    b[c] = static_cast<float>(std::cos(elevation) * std::sin(offset));
    if (config.firing_time_correction) {
      correction_rad_per_rpm[c] =
          static_cast<float>(6e-6 * (kChannelFiringOffsetNs[c] / 1000.0) * kDegToRad);
    }
    const ChannelAzimuthFixed fixed =
        channel_azimuth_fixed(calibration.azimuth_offset_deg[c], kChannelFiringOffsetNs[c],
                              config.firing_time_correction);
    offset_q[c] = fixed.offset_q;
    rpm_gain[c] = fixed.rpm_gain;
    channel_byte[c] = c << 24;
    firing_offset_ns[c] = kChannelFiringOffsetNs[c];
  }
  for (int i = 0; i < kAngleCoarseSteps; ++i) {
    const double angle = i * kAngleFineSteps * kCdegToRad;
    coarse_sin_cos[i] = {std::sin(angle), std::cos(angle)};
  }
  for (int i = 0; i < kAngleFineSteps; ++i) {
    fine_sin_cos[i] = {std::sin(i * kCdegToRad), std::cos(i * kCdegToRad)};
  }
}

SimdKernel simd_decoder_kernel(DecoderTarget target) noexcept {
  const KernelEntry* entry = find_kernel(target);
  return entry != nullptr ? entry->kernel : nullptr;
}

bool simd_target_supported(DecoderTarget target) noexcept {
  const KernelEntry* entry = find_kernel(target);
  return entry != nullptr && (hwy::SupportedTargets() & entry->hwy_target) != 0;
}

std::vector<DecoderTarget> compiled_decoder_targets() {
  std::vector<DecoderTarget> targets{DecoderTarget::kScalar};
  for (const KernelEntry& entry : kKernels)
    targets.push_back(entry.target);
  return targets;
}

std::vector<DecoderTarget> supported_decoder_targets() {
  std::vector<DecoderTarget> targets{DecoderTarget::kScalar};
  for (const KernelEntry& entry : kKernels) {
    if (simd_target_supported(entry.target)) targets.push_back(entry.target);
  }
  return targets;
}

PacketDecoder::PacketDecoder(const Calibration& calibration, const DecoderConfig& config,
                             DecoderTarget target)
    : scalar_(calibration, config), target_(target) {
  if (target == DecoderTarget::kScalar) return;
  if (!simd_target_supported(target)) {
    throw std::invalid_argument(
        std::string("decoder '") + std::string(to_string(target)) +
        "' cannot run here (supported: " + join_targets(supported_decoder_targets()) + ")");
  }
  simd_kernel_ = simd_decoder_kernel(target);
  simd_tables_ = std::make_unique<SimdDecoderTables>(calibration, config);
}

}  // namespace pandarcap
#endif  // HWY_ONCE
