// The PCD rows of core/frames/pcd.hpp encoded with SIMD, the bytes of encode_pcd_points (the
// scalar reference) exactly, for every layout and axes: what the frame cut writes into a frame's
// arena a block at a time (FrameAssembler).
//
// How: a vector of points is loaded as four 64-bit words each (x|y, z|distance, time, and the
// azimuth, intensity, channel and return-type bytes), de-interleaved, so every field is a lane of
// a vector; each layout's row is then built as up to four 64-bit words with shifts and ors, the
// conversions done lane-wise, and stored back interleaved: a 32-byte row per point, which the
// smaller layouts pack to their 22, 23 or 27 bytes with overlapping 32-byte copies.
//
// Exactness, against the reference's arithmetic:
//  - the epoch seconds (pcl, pandarcap) are whole seconds plus nanoseconds × 1e-9. The whole
//    seconds come from a division once per call, not per point: a point's nanoseconds are its
//    time minus the call's second, exact while it stays in that second (a vector that leaves it,
//    or a time before 1970, goes to the reference). The product and the sum round as the
//    reference's do: fused where the compiler fuses them there (__FP_FAST_FMA: ARM64), two
//    roundings elsewhere, with the product kept out of the compiler's reach so that an AVX2 or
//    AVX-512 kernel, which may fuse, does not;
//  - integers become doubles by the exponent trick (exact below 2^51) and floats by the
//    correctly rounded demotion the reference's casts also use;
//  - the autoware elevation is the reference's libm calls (atan2f of hypotf), per point, made
//    before the kernel runs.
// tests/test_pcd_simd_encoder.cpp compares the bytes with the reference on every target the
// machine runs, for every layout and axes, edge values and every count up to a few vectors.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>

#include "core/decode/decoder_target.hpp"
#include "core/frames/pcd.hpp"
#include "core/frames/point.hpp"

namespace pandarcap {

// What one call's kernel needs besides the points, worked out once per call.
struct PcdEncodeConstants {
  std::int64_t second_ns = 0;  // the whole second of the call's first point, in ns
  double second_s = 0;         // the same in seconds
  std::int64_t reference_ns = 0;
  std::uint8_t nebula_codes[4]{};    // nebula_return_type of each ReturnType in the frame's mode
  std::uint64_t zero = 0;            // 0, read at run time: keeps a product unfused (see above)
  const float* elevation = nullptr;  // autoware: the elevations of the points the kernel takes
};

// One target's kernel: encodes points[0..n) into out like encode_pcd_points, and returns how
// many it encoded, in order; it stops early at a vector it cannot encode exactly (a time outside
// the call's second), which the caller gives to the reference.
using PcdEncodeKernel = std::size_t (*)(const Point* points, std::size_t n, std::uint8_t* out,
                                        PcdFormat format, const PcdEncodeConstants& constants);

// The kernel built for `target`, or nullptr (scalar, or not in this binary). Does not check the
// CPU: simd_target_supported does.
PcdEncodeKernel pcd_encode_kernel(DecoderTarget target) noexcept;

class PcdEncoder {
 public:
  // The fastest target this CPU runs (best_decoder_target).
  PcdEncoder();
  // `target`'s kernel; the scalar reference for kScalar, or when the CPU or binary lacks it.
  explicit PcdEncoder(DecoderTarget target);

  // encode_pcd_points, the same bytes. No allocation.
  std::size_t encode(std::span<const Point> points, std::span<std::uint8_t> out, PcdFormat format,
                     PcdFrameContext frame) const noexcept;

  DecoderTarget target() const noexcept { return target_; }

 private:
  DecoderTarget target_ = DecoderTarget::kScalar;
  PcdEncodeKernel kernel_ = nullptr;
};

}  // namespace pandarcap
