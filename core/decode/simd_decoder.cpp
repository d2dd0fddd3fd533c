// The SIMD decoder's kernels, compiled once per instruction set by Google Highway
// (foreach_target re-includes this file for each target), and the table that picks one at run
// time. See simd_decoder.hpp for the arithmetic.
#include "core/decode/simd_decoder.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numbers>
#include <stdexcept>
#include <string>

#include "core/sensors/timing.hpp"

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "core/decode/simd_decoder.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

// Highway's one-lane HWY_SCALAR fallback (this build's baseline) is not a decoder target: the
// scalar reference is core/decode/decoder.cpp. Only real SIMD targets get a kernel.
#if HWY_TARGET != HWY_SCALAR
HWY_BEFORE_NAMESPACE();
namespace pandarcap {
namespace HWY_NAMESPACE {
namespace {

namespace hn = hwy::HWY_NAMESPACE;

constexpr int kLanes = SimdDecoderTables::kLanes;

// At most 16 lanes (3 vectors per block), so the padded per-channel arrays are large enough on
// scalable targets (SVE) too.
using DF = hn::CappedTag<float, 16>;
using DI = hn::RebindToSigned<DF>;
using DU = hn::RebindToUnsigned<DF>;
using DU8 = hn::Repartition<std::uint8_t, DI>;  // the bytes of one DI vector

// Unpacking 3-byte channel records with two shuffles: first whole 32-bit words, so that each
// 128-bit block holds the 12 bytes of 4 channels, then bytes within each block, so that each
// 32-bit lane holds one channel's distance (or reflectivity), zero-extended.
alignas(64) constexpr std::int32_t kRecordWords[16] = {0, 1, 2, 0, 3, 4,  5,  0,
                                                       6, 7, 8, 0, 9, 10, 11, 0};
constexpr std::uint8_t Z = 0x80;  // TableLookupBytesOr0: zero
alignas(64) constexpr std::uint8_t kDistanceBytes[64] = {
    0, 1,  Z, Z, 3, 4, Z, Z,  6, 7, Z, Z, 9, 10, Z, Z, 0, 1,  Z, Z, 3, 4,
    Z, Z,  6, 7, Z, Z, 9, 10, Z, Z, 0, 1, Z, Z,  3, 4, Z, Z,  6, 7, Z, Z,
    9, 10, Z, Z, 0, 1, Z, Z,  3, 4, Z, Z, 6, 7,  Z, Z, 9, 10, Z, Z};
alignas(64) constexpr std::uint8_t kReflectivityBytes[64] = {
    2,  Z, Z, Z, 5, Z, Z,  Z, 8, Z, Z, Z, 11, Z, Z, Z, 2,  Z, Z, Z, 5, Z,
    Z,  Z, 8, Z, Z, Z, 11, Z, Z, Z, 2, Z, Z,  Z, 5, Z, Z,  Z, 8, Z, Z, Z,
    11, Z, Z, Z, 2, Z, Z,  Z, 5, Z, Z, Z, 8,  Z, Z, Z, 11, Z, Z, Z};

// Bytes one block's loads read from its first channel record: the last vector starts at channel
// ((40 - 1) / N) * N and loads 4 N bytes.
std::size_t record_span() {
  const std::size_t n = hn::Lanes(DI());
  return 3 * (((kChannels - 1) / n) * n) + 4 * n;
}

// One block's points before compaction: every channel's 32 bytes, and which channels are kept.
struct BlockPoints {
  alignas(64) float xyzd[kLanes * 4];          // Point bytes 0..15: x, y, z, distance
  alignas(64) std::uint32_t tail[kLanes * 4];  // Point bytes 16..31: time, azimuth, ...
  std::uint64_t kept = 0;                      // bit c: channel c is kept
};

// The per-channel constants one packet uses: the calibration's, or rotated by the firing-time
// correction at this packet's RPM.
struct ChannelConstants {
  const float* a;
  const float* b;
  const std::int32_t* label_offset;  // offset_q (- correction), wrapped into [0, full), + 1/2
};

// Filter counts are lane-wise vectors (one subtract per mask), summed once per packet. They are
// separate locals of DecodeKernel, not members of a struct: SVE vectors are sizeless and cannot
// be members (nor can a record's two vectors, below).
HWY_INLINE void count(hn::Vec<DI>& counter, hn::Mask<DI> mask) {
  counter = hn::Sub(counter, hn::VecFromMask(DI(), mask));  // true lanes are -1
}

HWY_INLINE std::uint64_t total(hn::Vec<DI> counter) {
  return static_cast<std::uint64_t>(hn::GetLane(hn::SumOfLanes(DI(), counter)));
}

// The 3-byte records of channels i..i+N, regrouped so that each 128-bit block holds 4 of them;
// distance() and reflectivity() then pick their bytes.
HWY_INLINE hn::Vec<DU8> load_records(const std::uint8_t* records, std::size_t i) {
  const DI di;
  const DU8 d8;
  const auto words = hn::TableLookupLanes(hn::BitCast(di, hn::LoadU(d8, records + 3 * i)),
                                          hn::SetTableIndices(di, kRecordWords));
  return hn::BitCast(d8, words);
}

HWY_INLINE hn::Vec<DI> distance(hn::Vec<DU8> records) {
  return hn::BitCast(DI(), hn::TableLookupBytesOr0(records, hn::Load(DU8(), kDistanceBytes)));
}

HWY_INLINE hn::Vec<DI> reflectivity(hn::Vec<DU8> records) {
  return hn::BitCast(DI(), hn::TableLookupBytesOr0(records, hn::Load(DU8(), kReflectivityBytes)));
}

// Lanes of real channels (the last vector of a 16-lane target covers channels 32..47).
HWY_INLINE hn::Mask<DI> real_channels(std::size_t i) {
  const DI di;
  return hn::Lt(hn::Iota(di, static_cast<std::int32_t>(i)), hn::Set(di, kChannels));
}

// The range filter on one vector of distances; counts each reason once per real channel into
// the packet's lane-wise counters.
HWY_INLINE hn::Mask<DI> in_range(const SimdDecoderTables& t, hn::Vec<DI> raw, hn::Mask<DI> real,
                                 hn::Vec<DI>& no_return, hn::Vec<DI>& below_min,
                                 hn::Vec<DI>& above_max) {
  const DI di;
  const auto zero = hn::And(hn::Eq(raw, hn::Zero(di)), real);
  const auto returned = hn::AndNot(zero, real);
  const auto below =
      hn::And(hn::Lt(raw, hn::Set(di, static_cast<std::int32_t>(t.limits.min))), returned);
  const auto above =
      hn::And(hn::Gt(raw, hn::Set(di, static_cast<std::int32_t>(t.limits.max))), returned);
  count(no_return, zero);
  count(below_min, below);
  count(above_max, above);
  return hn::AndNot(hn::Or(below, above), returned);
}

// What one block needs besides its records.
struct BlockContext {
  float sin_azimuth, cos_azimuth;
  std::int32_t azimuth_q;  // block azimuth x kAzimuthQ
  std::int64_t time_ns;    // t0 + block offset; a point's time is this - firing offset
};

// Computes one vector of points (channels i..i+N) of a block into `out`.
HWY_INLINE void emit(const SimdDecoderTables& t, const ChannelConstants& k, std::size_t i,
                     const BlockContext& block, hn::Vec<DI> distance_raw,
                     hn::Vec<DI> reflectivity_raw, hn::Vec<DI> return_type, hn::Mask<DI> keep,
                     BlockPoints& out) {
  const DF df;
  const DI di;
  const DU du;
  // Nothing kept (no returns, or a dual pair merged into the strongest echo): nothing to build.
  if (hn::AllFalse(di, keep)) return;

  const auto r =
      hn::Mul(hn::ConvertTo(df, distance_raw), hn::Set(df, static_cast<float>(kDistanceUnitM)));
  const auto a = hn::Load(df, k.a + i);
  const auto b = hn::Load(df, k.b + i);
  const auto sin_a = hn::Set(df, block.sin_azimuth);
  const auto cos_a = hn::Set(df, block.cos_azimuth);
  // sin(A + o) cos ω and cos(A + o) cos ω by angle addition.
  const auto x = hn::Mul(r, hn::MulAdd(sin_a, a, hn::Mul(cos_a, b)));
  const auto y = hn::Mul(r, hn::NegMulAdd(sin_a, b, hn::Mul(cos_a, a)));
  const auto z = hn::Mul(r, hn::Load(df, t.sin_elevation.data() + i));
  hn::StoreInterleaved4(x, y, z, r, df, out.xyzd + 4 * i);

  // The azimuth label: the same value as corrected_azimuth_cdeg, with the half step for
  // rounding folded into the per-channel offset so one wrap suffices.
  auto q = hn::Add(hn::Set(di, block.azimuth_q), hn::Load(di, k.label_offset + i));
  q = hn::IfThenElse(hn::Gt(q, hn::Set(di, kFullCircleQ - 1)),
                     hn::Sub(q, hn::Set(di, kFullCircleQ)), q);
  static_assert(kAzimuthQ == 1 << 10);
  const auto cdeg = hn::ShiftRight<10>(q);

  // Point bytes 16..31: time (i64 as two u32 with borrow), then azimuth (u16), intensity,
  // channel, return type and 3 reserved zero bytes.
  const auto time_low = static_cast<std::uint32_t>(static_cast<std::uint64_t>(block.time_ns));
  const auto time_high =
      static_cast<std::uint32_t>(static_cast<std::uint64_t>(block.time_ns) >> 32);
  const auto firing =
      hn::Load(du, reinterpret_cast<const std::uint32_t*>(t.firing_offset_ns.data()) + i);
  const auto low = hn::Sub(hn::Set(du, time_low), firing);
  const auto borrow = hn::Lt(hn::Set(di, static_cast<std::int32_t>(time_low ^ 0x80000000u)),
                             hn::Load(di, t.firing_offset_biased.data() + i));
  const auto high = hn::Add(hn::Set(du, time_high), hn::BitCast(du, hn::VecFromMask(di, borrow)));
  const auto meta = hn::Or(hn::Or(cdeg, hn::ShiftLeft<16>(reflectivity_raw)),
                           hn::Load(di, t.channel_byte.data() + i));
  hn::StoreInterleaved4(low, high, hn::BitCast(du, meta), hn::BitCast(du, return_type), du,
                        out.tail + 4 * i);

  // A bit mask rather than CompressStore: Highway 1.0.3's AVX2 compress copies a 1 KB index
  // table per call, and write_points walks the kept channels anyway.
  std::uint8_t bits[8] = {};
  hn::StoreMaskBits(di, keep, bits);
  std::uint64_t kept = 0;
  std::memcpy(&kept, bits, sizeof kept);
  out.kept |= kept << i;
}

// Writes the kept points of one block, in channel order, from out[n]; returns the new n.
HWY_INLINE std::size_t write_points(const BlockPoints& block, Point* out, std::size_t n) {
  static_assert(offsetof(Point, x) == 0 && offsetof(Point, distance_m) == 12);
  static_assert(offsetof(Point, timestamp_ns) == 16 && offsetof(Point, azimuth_cdeg) == 24);
  static_assert(offsetof(Point, intensity) == 26 && offsetof(Point, channel) == 27);
  static_assert(offsetof(Point, return_type) == 28);
  for (std::uint64_t kept = block.kept; kept != 0; kept &= kept - 1, ++n) {
    const auto c = static_cast<std::size_t>(__builtin_ctzll(kept));
    auto* bytes = reinterpret_cast<unsigned char*>(out + n);
    std::memcpy(bytes, block.xyzd + 4 * c, 16);
    std::memcpy(bytes + 16, block.tail + 4 * c, 16);
  }
  return n;
}

ChannelConstants channel_constants(const SimdDecoderTables& t, int rpm, float* a, float* b,
                                   std::int32_t* label_offset) {
  if (!t.firing_time_correction) return {t.a.data(), t.b.data(), t.label_offset.data()};
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
    // offset_q - correction, wrapped into [0, full), + the half step (see emit).
    const auto gain = hn::Load(di, t.rpm_gain.data() + i);
    const auto correction = hn::ShiftRight<8>(hn::Add(hn::Mul(vrpm_i, gain), hn::Set(di, 128)));
    auto offset = hn::Sub(hn::Load(di, t.offset_q.data() + i), correction);
    offset = hn::IfThenElse(hn::Lt(offset, hn::Zero(di)),
                            hn::Add(offset, hn::Set(di, kFullCircleQ)), offset);
    hn::Store(hn::Add(offset, hn::Set(di, kAzimuthQ / 2)), di, label_offset + i);
  }
  return {a, b, label_offset};
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
  alignas(64) std::int32_t rotated_offset[kLanes];
  const ChannelConstants k = channel_constants(t, rpm, rotated_a, rotated_b, rotated_offset);

  // Loads read whole vectors; where that would run past the packet (the last block, on wide
  // targets), they read a zero-padded copy instead.
  alignas(64) std::uint8_t padded[192] = {};
  const std::uint8_t* records[kBlocks];
  for (int b = 0; b < kBlocks; ++b)
    records[b] = packet.block(b) + 4;
  if (kBlockBytes * (kBlocks - 1) + 4 + record_span() > packet.bytes().size()) {
    std::memcpy(padded, records[kBlocks - 1], 3 * kChannels);
    records[kBlocks - 1] = padded;
  }

  // sin and cos of each block azimuth: coarse and fine table entries combined in double.
  BlockContext blocks[kBlocks];
  for (int b = 0; b < kBlocks; ++b) {
    const unsigned azimuth = packet.azimuth_cdeg(b);  // < 36000: validate() checked it
    const auto& coarse = t.coarse_sin_cos[azimuth / SimdDecoderTables::kAngleFineSteps];
    const auto& fine = t.fine_sin_cos[azimuth % SimdDecoderTables::kAngleFineSteps];
    blocks[b].sin_azimuth = static_cast<float>(coarse[0] * fine[1] + coarse[1] * fine[0]);
    blocks[b].cos_azimuth = static_cast<float>(coarse[1] * fine[1] - coarse[0] * fine[0]);
    blocks[b].azimuth_q = static_cast<std::int32_t>(azimuth) * kAzimuthQ;
    blocks[b].time_ns = t0_ns + block_offset_ns(b, mode);
  }

  DecodedPacket result;
  auto no_return = hn::Zero(di), below = hn::Zero(di), above = hn::Zero(di);
  auto duplicate = hn::Zero(di), too_close = hn::Zero(di);
  std::size_t n = 0;
  BlockPoints points[2];

  if (mode != ReturnMode::kDual) {
    const auto single = hn::Set(di, static_cast<std::int32_t>(ReturnType::kSingle));
    for (int b = 0; b < kBlocks; ++b) {
      points[0].kept = 0;
      for (std::size_t i = 0; i < static_cast<std::size_t>(kChannels); i += lanes) {
        const auto r = load_records(records[b], i);
        const auto d = distance(r);
        const auto keep = in_range(t, d, real_channels(i), no_return, below, above);
        emit(t, k, i, blocks[b], d, reflectivity(r), single, keep, points[0]);
      }
      result.block_begin[b] = static_cast<std::uint16_t>(n);
      n = write_points(points[0], out, n);
    }
  } else {
    const auto last = hn::Set(di, static_cast<std::int32_t>(ReturnType::kLast));
    const auto strongest = hn::Set(di, static_cast<std::int32_t>(ReturnType::kStrongest));
    const auto merged_type = hn::Set(di, static_cast<std::int32_t>(ReturnType::kLastStrongest));
    const auto threshold = hn::Set(di, static_cast<std::int32_t>(t.limits.dual_threshold));
    for (int b = 0; b < kBlocks; b += 2) {
      points[0].kept = points[1].kept = 0;
      for (std::size_t i = 0; i < static_cast<std::size_t>(kChannels); i += lanes) {
        const auto real = real_channels(i);
        const auto r_last = load_records(records[b], i);
        const auto r_strongest = load_records(records[b + 1], i);
        const auto d_last = distance(r_last), d_strongest = distance(r_strongest);
        const auto f_last = reflectivity(r_last), f_strongest = reflectivity(r_strongest);
        auto keep_last = in_range(t, d_last, real, no_return, below, above);
        const auto keep_strongest = in_range(t, d_strongest, real, no_return, below, above);
        // Both echoes kept: identical, or closer than the threshold, keeps only the odd block's.
        const auto both = hn::And(keep_last, keep_strongest);
        const auto identical =
            hn::And(both, hn::And(hn::Eq(d_last, d_strongest), hn::Eq(f_last, f_strongest)));
        const auto close = hn::And(hn::AndNot(identical, both),
                                   hn::Lt(hn::Abs(hn::Sub(d_last, d_strongest)), threshold));
        const auto merged = hn::Or(identical, close);
        count(duplicate, identical);
        count(too_close, close);
        keep_last = hn::AndNot(merged, keep_last);
        emit(t, k, i, blocks[b], d_last, f_last, last, keep_last, points[0]);
        emit(t, k, i, blocks[b + 1], d_strongest, f_strongest,
             hn::IfThenElse(merged, merged_type, strongest), keep_strongest, points[1]);
      }
      result.block_begin[b] = static_cast<std::uint16_t>(n);
      n = write_points(points[0], out, n);
      result.block_begin[b + 1] = static_cast<std::uint16_t>(n);
      n = write_points(points[1], out, n);
    }
  }
  result.block_begin[kBlocks] = static_cast<std::uint16_t>(n);
  result.point_count = static_cast<std::uint16_t>(n);
  filtered.add(FilterReason::kNoReturn, total(no_return));
  filtered.add(FilterReason::kBelowMinRange, total(below));
  filtered.add(FilterReason::kAboveMaxRange, total(above));
  filtered.add(FilterReason::kDualDuplicate, total(duplicate));
  filtered.add(FilterReason::kDualTooClose, total(too_close));
  return result;
}

}  // namespace HWY_NAMESPACE
}  // namespace pandarcap
HWY_AFTER_NAMESPACE();
#endif  // HWY_TARGET != HWY_SCALAR

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
    label_offset[c] = fixed.offset_q + kAzimuthQ / 2;
    rpm_gain[c] = fixed.rpm_gain;
    channel_byte[c] = c << 24;
    firing_offset_ns[c] = kChannelFiringOffsetNs[c];
    firing_offset_biased[c] = static_cast<std::int32_t>(
        static_cast<std::uint32_t>(kChannelFiringOffsetNs[c]) ^ 0x80000000u);
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

}  // namespace pandarcap
#endif  // HWY_ONCE
