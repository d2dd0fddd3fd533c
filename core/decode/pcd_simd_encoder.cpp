// The PCD row kernels, compiled once per instruction set by Google Highway (foreach_target
// re-includes this file for each target, as for the decoder), and the encoder that picks one.
// See pcd_simd_encoder.hpp for the layout of the work and why each conversion is exact.
#include "core/decode/pcd_simd_encoder.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <numbers>

#include "core/decode/simd_decoder.hpp"  // simd_target_supported

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "core/decode/pcd_simd_encoder.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

// As for the decoder: no kernel for Highway's one-lane fallback; the reference is pcd.cpp.
#if HWY_TARGET != HWY_SCALAR
HWY_BEFORE_NAMESPACE();
namespace pandarcap {
namespace HWY_NAMESPACE {
namespace {

namespace hn = hwy::HWY_NAMESPACE;

// One lane per point, at most 4 (256 bits: a point's row is 256 bits, so a vector of rows is
// regrouped from four vectors with two rounds of shuffles; AVX-512 and wide SVE run 256-bit
// vectors). The row buffers below are sized for it.
constexpr std::size_t kMaxLanes = 4;
using D = hn::CappedTag<std::uint64_t, kMaxLanes>;
using DI = hn::RebindToSigned<D>;
using DF = hn::RebindToFloat<D>;
using DF32 = hn::Repartition<float, D>;  // two floats in each lane
using DF32H = hn::Rebind<float, D>;      // one float per lane, half as wide
using DU32H = hn::Rebind<std::uint32_t, D>;

static_assert(sizeof(Point) == 32 && offsetof(Point, timestamp_ns) == 16 &&
              offsetof(Point, azimuth_cdeg) == 24 && offsetof(Point, intensity) == 26 &&
              offsetof(Point, channel) == 27 && offsetof(Point, return_type) == 28);

// 2^52 as a double's bits: an integer 0 <= i < 2^52 or'ed in is exactly 2^52 + i.
constexpr std::uint64_t kTwo52Bits = 0x4330000000000000ULL;
constexpr double kTwo52 = 4503599627370496.0;
// 1.5 × 2^52: a signed -2^51 <= i < 2^51 added to its bits is exactly 1.5 × 2^52 + i.
constexpr std::int64_t kOneAndHalfTwo52Bits = 0x4338000000000000LL;
constexpr double kOneAndHalfTwo52 = 6755399441055744.0;
constexpr std::int64_t kTwo51 = std::int64_t{1} << 51;

// Unsigned 0 <= v < 2^52 to double, exactly.
HWY_INLINE hn::Vec<DF> to_double(hn::Vec<D> v) {
  return hn::Sub(hn::BitCast(DF(), hn::Or(v, hn::Set(D(), kTwo52Bits))), hn::Set(DF(), kTwo52));
}

// Signed -2^51 <= v < 2^51 to double, exactly.
HWY_INLINE hn::Vec<DF> to_double_signed(hn::Vec<DI> v) {
  return hn::Sub(hn::BitCast(DF(), hn::Add(v, hn::Set(DI(), kOneAndHalfTwo52Bits))),
                 hn::Set(DF(), kOneAndHalfTwo52));
}

// Doubles rounded to floats (as static_cast<float>), each float's bits in its lane's low half.
HWY_INLINE hn::Vec<D> float_bits(hn::Vec<DF> v) {
  return hn::PromoteTo(D(), hn::BitCast(DU32H(), hn::DemoteTo(DF32H(), v)));
}

using DI32 = hn::Repartition<std::int32_t, D>;  // two int32 in each lane
using DU32 = hn::Repartition<std::uint32_t, D>;
using DU8 = hn::Repartition<std::uint8_t, D>;

// Whether any lane is negative (its sign bit set).
HWY_INLINE bool any_negative(hn::Vec<DI> v) {
  return !hn::AllFalse(DI(), hn::Lt(v, hn::Zero(DI())));
}

// The 32-bit halves: odd from `odd` (the lane's bytes 4-7), even from `even` (bytes 0-3).
HWY_INLINE hn::Vec<D> halves(hn::Vec<D> odd, hn::Vec<D> even) {
  return hn::BitCast(D(), hn::OddEven(hn::BitCast(DU32(), odd), hn::BitCast(DU32(), even)));
}

// Bytes of each lane picked by `table` (16 indices, the same in every 128-bit block; 0x80: 0).
HWY_INLINE hn::Vec<D> pick_bytes(hn::Vec<D> v, const std::uint8_t* table) {
  const DU8 d8;
  return hn::BitCast(D(), hn::TableLookupBytesOr0(hn::BitCast(d8, v), hn::LoadDup128(d8, table)));
}

constexpr std::uint8_t Z = 0x80;
// From the point's meta word (azimuth 0-1, intensity 2, channel 3, return type 4):
alignas(16) constexpr std::uint8_t kIntensityHigh[16] = {Z, Z, Z, Z, 2,  Z, Z, Z,
                                                         Z, Z, Z, Z, 10, Z, Z, Z};
alignas(16) constexpr std::uint8_t kChannelZeroType[16] = {3,  Z, 4,  Z, Z, Z, Z, Z,
                                                           11, Z, 12, Z, Z, Z, Z, Z};
alignas(16) constexpr std::uint8_t kChannel[16] = {3, Z, Z, Z, Z, Z, Z, Z, 11, Z, Z, Z, Z, Z, Z, Z};
alignas(16) constexpr std::uint8_t kIntensityChannelTypeHigh[16] = {Z, Z, Z, Z, 2,  3,  4,  Z,
                                                                    Z, Z, Z, Z, 10, 11, 12, Z};

// z in the low half and the intensity as a float (exact: 0..255) in the high half.
HWY_INLINE hn::Vec<D> z_and_float_intensity(hn::Vec<D> zd, hn::Vec<D> meta) {
  const auto intensity = hn::ConvertTo(hn::Repartition<float, D>(),
                                       hn::BitCast(DI32(), pick_bytes(meta, kIntensityHigh)));
  return halves(hn::BitCast(D(), intensity), zd);
}

// The epoch seconds of times in the call's second (pcd.cpp's epoch_seconds), as double bits;
// false if a lane is outside that second.
HWY_INLINE bool epoch_seconds(hn::Vec<D> time, const PcdEncodeConstants& c, hn::Vec<D>& bits) {
  const DI di;
  const auto ns = hn::Sub(hn::BitCast(di, time), hn::Set(di, c.second_ns));
  // Negative either way when ns < 0 or ns > 999 999 999.
  if (any_negative(hn::Or(ns, hn::Sub(hn::Set(di, 999'999'999), ns)))) return false;
  const auto fraction = to_double(hn::BitCast(D(), ns));
#if defined(__FP_FAST_FMA)
  // The reference is fused here (see pcd.cpp): one rounding.
  const auto seconds = hn::MulAdd(fraction, hn::Set(DF(), 1e-9), hn::Set(DF(), c.second_s));
#else
  // Two roundings, as the reference's: the product goes through an integer or with a run-time
  // zero, so no target that has FMA can fuse it with the sum.
  const auto product = hn::BitCast(
      DF(), hn::Or(hn::BitCast(D(), hn::Mul(fraction, hn::Set(DF(), 1e-9))), hn::Set(D(), c.zero)));
  const auto seconds = hn::Add(hn::Set(DF(), c.second_s), product);
#endif
  bits = hn::BitCast(D(), seconds);
  return true;
}

// Nanoseconds since the frame's reference; false if a lane is 2^51 or more away.
HWY_INLINE bool since_reference(hn::Vec<D> time, const PcdEncodeConstants& c, hn::Vec<DI>& since) {
  const DI di;
  since = hn::Sub(hn::BitCast(di, time), hn::Set(di, c.reference_ns));
  // Negative either way when since < -2^51 or since >= 2^51.
  return !any_negative(
      hn::Or(hn::Add(since, hn::Set(di, kTwo51)), hn::Sub(hn::Set(di, kTwo51 - 1), since)));
}

// One vector of points (Lanes(D()) of them at `src`) as their rows' four words, w0 the row's
// bytes 0-7 and so on. False when one of them must go to the reference.
// `elevation`: the autoware layout's elevations of these points (nullptr for the others).
template <PcdLayout Layout, bool Ros>
HWY_INLINE bool encode_vector(const std::uint8_t* src, const float* elevation,
                              const PcdEncodeConstants& c, hn::Vec<D>& w0, hn::Vec<D>& w1,
                              hn::Vec<D>& w2, hn::Vec<D>& w3) {
  const D d;
  const DI di;
  hn::Vec<D> xy, zd, time, meta;
  hn::LoadInterleaved4(d, reinterpret_cast<const std::uint64_t*>(src), xy, zd, time, meta);
  // x y (ros: y, -x: the halves swapped and the new high half's sign flipped, as negation does).
  w0 = xy;
  if constexpr (Ros) {
    w0 = hn::Xor(hn::Or(hn::ShiftLeft<32>(xy), hn::ShiftRight<32>(xy)),
                 hn::Set(d, 0x8000000000000000ULL));
  }
  w3 = hn::Zero(d);

  if constexpr (Layout == PcdLayout::kPcl) {
    // x y z | intensity F4 | ring U2 | return_type U1 | timestamp F8
    hn::Vec<D> seconds;
    if (!epoch_seconds(time, c, seconds)) return false;
    w1 = z_and_float_intensity(zd, meta);
    w2 = hn::Or(pick_bytes(meta, kChannelZeroType), hn::ShiftLeft<24>(seconds));
    w3 = hn::ShiftRight<40>(seconds);
  } else if constexpr (Layout == PcdLayout::kPandarcap) {
    // x y z | intensity U1 | channel U1 | return_type U1 | timestamp F8: the three bytes are the
    // point's own, in the same order.
    hn::Vec<D> seconds;
    if (!epoch_seconds(time, c, seconds)) return false;
    w1 =
        hn::Or(halves(pick_bytes(meta, kIntensityChannelTypeHigh), zd), hn::ShiftLeft<56>(seconds));
    w2 = hn::ShiftRight<8>(seconds);
  } else if constexpr (Layout == PcdLayout::kVelodyne) {
    // x y z | intensity F4 | ring U2 | time F4 (s since the reference)
    hn::Vec<DI> since;
    if (!since_reference(time, c, since)) return false;
    const auto seconds = float_bits(hn::Mul(to_double_signed(since), hn::Set(DF(), 1e-9)));
    w1 = z_and_float_intensity(zd, meta);
    w2 = hn::Or(pick_bytes(meta, kChannel), hn::ShiftLeft<16>(seconds));
  } else {
    // x y z | intensity U1 | return_type U1 (nebula's) | channel U2 | azimuth F4 | elevation F4 |
    // distance F4 | time_stamp U4 (ns since the reference, modulo 2^32 before it)
    const auto low_half = hn::Set(d, 0xFFFFFFFFULL);
    const auto byte = hn::Set(d, 0xFFULL);
    const auto intensity = hn::And(hn::ShiftRight<16>(meta), byte);
    const auto channel = hn::And(hn::ShiftRight<24>(meta), byte);
    const auto type = hn::And(hn::ShiftRight<32>(meta), byte);
    const auto since = hn::Sub(hn::BitCast(di, time), hn::Set(di, c.reference_ns));
    const auto cap = hn::Set(di, 0xFFFFFFFFLL);
    const auto stamp =
        hn::And(hn::BitCast(d, hn::IfThenElse(hn::Gt(since, cap), cap, since)), low_half);
    auto code = hn::Zero(d);
    for (std::uint64_t t = 0; t < 4; ++t) {
      code = hn::IfThenElse(hn::Eq(type, hn::Set(d, t)), hn::Set(d, c.nebula_codes[t]), code);
    }
    w1 = hn::Or(hn::Or(hn::And(zd, low_half), hn::ShiftLeft<32>(intensity)),
                hn::Or(hn::ShiftLeft<40>(code), hn::ShiftLeft<48>(channel)));
    const auto azimuth = hn::Mul(to_double(hn::And(meta, hn::Set(d, 0xFFFFULL))),
                                 hn::Set(DF(), std::numbers::pi / 18000.0));
    const auto elevation_bits =
        hn::PromoteTo(d, hn::LoadU(DU32H(), reinterpret_cast<const std::uint32_t*>(elevation)));
    w2 = hn::Or(float_bits(azimuth), hn::ShiftLeft<32>(elevation_bits));
    w3 = hn::Or(hn::ShiftRight<32>(zd), hn::ShiftLeft<32>(stamp));
  }
  return true;
}

// Stores one vector's rows, row j as 32 bytes at out + kRow × j, in order, so that each row
// overwrites the excess of the one before it. The rows are the words transposed: interleaved in
// pairs within each 128-bit block, then (256-bit vectors) the blocks regrouped.
template <std::size_t kRow>
HWY_INLINE void store_rows(hn::Vec<D> w0, hn::Vec<D> w1, hn::Vec<D> w2, hn::Vec<D> w3,
                           std::uint8_t* out) {
  const D d;
  const hn::Repartition<std::uint8_t, D> d8;
  const auto t0 = hn::InterleaveLower(d, w0, w1);  // rows 0 (and 2): bytes 0-15
  const auto t1 = hn::InterleaveUpper(d, w0, w1);  // rows 1 (and 3): bytes 0-15
  const auto t2 = hn::InterleaveLower(d, w2, w3);  // rows 0 (and 2): bytes 16-31
  const auto t3 = hn::InterleaveUpper(d, w2, w3);  // rows 1 (and 3): bytes 16-31
  if (hn::Lanes(d) == 4) {
    hn::StoreU(hn::BitCast(d8, hn::ConcatLowerLower(d, t2, t0)), d8, out);
    hn::StoreU(hn::BitCast(d8, hn::ConcatLowerLower(d, t3, t1)), d8, out + kRow);
    hn::StoreU(hn::BitCast(d8, hn::ConcatUpperUpper(d, t2, t0)), d8, out + 2 * kRow);
    hn::StoreU(hn::BitCast(d8, hn::ConcatUpperUpper(d, t3, t1)), d8, out + 3 * kRow);
  } else {
    // Two lanes (128-bit targets): each interleaved pair is half a row.
    hn::StoreU(hn::BitCast(d8, t0), d8, out);
    hn::StoreU(hn::BitCast(d8, t2), d8, out + 16);
    hn::StoreU(hn::BitCast(d8, t1), d8, out + kRow);
    hn::StoreU(hn::BitCast(d8, t3), d8, out + kRow + 16);
  }
}

template <PcdLayout Layout, bool Ros>
HWY_NOINLINE std::size_t encode_rows(const Point* points, std::size_t n, std::uint8_t* out,
                                     const PcdEncodeConstants& c) {
  constexpr std::size_t kRow = Layout == PcdLayout::kPcl         ? 27
                               : Layout == PcdLayout::kPandarcap ? 23
                               : Layout == PcdLayout::kVelodyne  ? 22
                                                                 : 32;
  const D d;
  const std::size_t lanes = hn::Lanes(d);
  const auto* src = reinterpret_cast<const std::uint8_t*>(points);
  hn::Vec<D> w0, w1, w2, w3;
  std::size_t i = 0;
  // Whole vectors straight into `out` while a point follows them: a row's excess past its 22, 23
  // or 27 bytes lands on the next row, which is written after it.
  for (; i + lanes < n || (kRow == 32 && i + lanes == n); i += lanes) {
    const float* elevation = Layout == PcdLayout::kAutoware ? c.elevation + i : nullptr;
    if (!encode_vector<Layout, Ros>(src + 32 * i, elevation, c, w0, w1, w2, w3)) return i;
    store_rows<kRow>(w0, w1, w2, w3, out + kRow * i);
  }
  if (i == n) return n;
  // The last 1..lanes points, with their rows copied at their exact size so that nothing is
  // written past the points: as the last whole vector of the call when there is one (rows before
  // `i` encoded again, to the same bytes), else from a copy padded with the last point.
  const std::uint8_t* last = src + 32 * (n - lanes);
  std::size_t from = n - lanes;
  alignas(64) std::uint8_t padded[32 * kMaxLanes];
  float padded_elevation[kMaxLanes] = {};
  const float* elevation = Layout == PcdLayout::kAutoware ? c.elevation + from : nullptr;
  if (n < lanes) {
    for (std::size_t j = 0; j < lanes; ++j) {
      std::memcpy(padded + 32 * j, src + 32 * std::min(j, n - 1), 32);
      if constexpr (Layout == PcdLayout::kAutoware) {
        padded_elevation[j] = c.elevation[std::min(j, n - 1)];
      }
    }
    last = padded;
    from = 0;
    elevation = padded_elevation;
  }
  if (!encode_vector<Layout, Ros>(last, elevation, c, w0, w1, w2, w3)) return i;
  alignas(64) std::uint8_t rows[32 * kMaxLanes];
  store_rows<32>(w0, w1, w2, w3, rows);
  for (std::size_t j = i - from; j < std::min(lanes, n); ++j)
    std::memcpy(out + kRow * (from + j), rows + 32 * j, kRow);
  return n;
}

template <PcdLayout Layout>
std::size_t encode_layout(const Point* points, std::size_t n, std::uint8_t* out, Axes axes,
                          const PcdEncodeConstants& c) {
  return axes == Axes::kRos ? encode_rows<Layout, true>(points, n, out, c)
                            : encode_rows<Layout, false>(points, n, out, c);
}

}  // namespace

std::size_t EncodeKernel(const Point* points, std::size_t n, std::uint8_t* out, PcdFormat format,
                         const PcdEncodeConstants& c) {
  switch (format.layout) {
    case PcdLayout::kPcl:
      return encode_layout<PcdLayout::kPcl>(points, n, out, format.axes, c);
    case PcdLayout::kPandarcap:
      return encode_layout<PcdLayout::kPandarcap>(points, n, out, format.axes, c);
    case PcdLayout::kVelodyne:
      return encode_layout<PcdLayout::kVelodyne>(points, n, out, format.axes, c);
    case PcdLayout::kAutoware:
      return encode_layout<PcdLayout::kAutoware>(points, n, out, format.axes, c);
  }
  return 0;
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
  PcdEncodeKernel kernel;
};

// The decoder's targets (simd_decoder.cpp), the same names and the same CPU checks.
constexpr KernelEntry kKernels[] = {
#if HWY_TARGETS & HWY_SSE4
    {DecoderTarget::kSse4, &N_SSE4::EncodeKernel},
#endif
#if HWY_TARGETS & HWY_AVX2
    {DecoderTarget::kAvx2, &N_AVX2::EncodeKernel},
#endif
#if HWY_TARGETS & HWY_AVX3
    {DecoderTarget::kAvx512, &N_AVX3::EncodeKernel},
#endif
#if HWY_TARGETS & HWY_NEON
    {DecoderTarget::kNeon, &N_NEON::EncodeKernel},
#endif
#if HWY_TARGETS & HWY_SVE
    {DecoderTarget::kSve, &N_SVE::EncodeKernel},
#endif
#if HWY_TARGETS & HWY_SVE2
    {DecoderTarget::kSve2, &N_SVE2::EncodeKernel},
#endif
};

// The most points the reference takes at once when the kernel cannot (a vector's worth).
constexpr std::size_t kReferenceRun = 8;
// Points whose autoware elevations are worked out before the kernel takes them.
constexpr std::size_t kElevationRun = 256;

}  // namespace

PcdEncodeKernel pcd_encode_kernel(DecoderTarget target) noexcept {
  for (const KernelEntry& entry : kKernels) {
    if (entry.target == target) return entry.kernel;
  }
  return nullptr;
}

PcdEncoder::PcdEncoder() : PcdEncoder(best_decoder_target()) {}

PcdEncoder::PcdEncoder(DecoderTarget target) {
  if (target != DecoderTarget::kScalar && simd_target_supported(target)) {
    kernel_ = pcd_encode_kernel(target);
  }
  target_ = kernel_ != nullptr ? target : DecoderTarget::kScalar;
}

std::size_t PcdEncoder::encode(std::span<const Point> points, std::span<std::uint8_t> out,
                               PcdFormat format, PcdFrameContext frame) const noexcept {
  if (kernel_ == nullptr) return encode_pcd_points(points, out, format, frame);
  const std::size_t step = pcd_point_bytes(format.layout);
  PcdEncodeConstants c;
  c.reference_ns = frame.reference_ns;
  if (format.layout == PcdLayout::kAutoware) {
    for (std::size_t t = 0; t < 4; ++t) {
      c.nebula_codes[t] = nebula_return_type(static_cast<ReturnType>(t), frame.return_mode);
    }
  }
  const bool epoch = format.layout == PcdLayout::kPcl || format.layout == PcdLayout::kPandarcap;
  std::size_t done = 0;
  if (format.layout == PcdLayout::kAutoware) {
    // The elevations first, a run at a time, by the reference's libm calls (here, outside the
    // kernels: the same calls, and no vector state to save around them), from the point's own
    // x y z whatever the axes.
    std::array<float, kElevationRun> elevation;
    c.elevation = elevation.data();
    while (done < points.size()) {
      const std::size_t run = std::min(kElevationRun, points.size() - done);
      for (std::size_t i = 0; i < run; ++i) {
        const Point& p = points[done + i];
        elevation[i] = std::atan2(p.z, std::hypot(p.x, p.y));
      }
      // Every time is exact here: the kernel takes all of them.
      done += kernel_(points.data() + done, run, out.data() + done * step, format, c);
    }
    return done * step;
  }
  while (done < points.size()) {
    const std::int64_t first = points[done].timestamp_ns;
    std::size_t encoded = 0;
    // The epoch layouts count from the second of the first point not yet encoded; times before
    // 1970 (the division rounds them the other way) are the reference's.
    if (!epoch || first >= 0) {
      c.second_ns = first / 1'000'000'000 * 1'000'000'000;
      c.second_s = static_cast<double>(first / 1'000'000'000);
      encoded =
          kernel_(points.data() + done, points.size() - done, out.data() + done * step, format, c);
    }
    done += encoded;
    if (encoded == 0) {
      const std::size_t run = std::min(kReferenceRun, points.size() - done);
      encode_pcd_points(points.subspan(done, run), out.subspan(done * step, run * step), format,
                        frame);
      done += run;
    }
  }
  return done * step;
}

}  // namespace pandarcap
#endif  // HWY_ONCE
