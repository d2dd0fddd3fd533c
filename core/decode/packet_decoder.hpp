// PacketDecoder: the scalar reference or a SIMD kernel behind one call, chosen once at start-up.
//
// What the stream decoder and the benchmarks hold. Both decoders give the same points (see
// simd_decoder.hpp for how the SIMD one is checked against the reference), so the choice is only
// speed; it is never made silently: a SIMD target this CPU cannot run is refused, not replaced.
#pragma once

#include <memory>
#include <span>

#include "core/decode/calibration.hpp"
#include "core/decode/decoder.hpp"
#include "core/decode/decoder_target.hpp"
#include "core/decode/simd_decoder.hpp"
#include "core/frames/point.hpp"
#include "core/sensors/packet.hpp"

namespace pandarcap {

// The scalar reference is always constructed (the frame assembler asks it for azimuth
// bounds); the SIMD decoder only when a SIMD target is chosen.
class PacketDecoder {
 public:
  // Throws std::invalid_argument when a SIMD `target` is not compiled in or this CPU cannot run
  // it (supported_decoder_targets() says which can): never a silent fallback.
  PacketDecoder(const Calibration& calibration, const DecoderConfig& config, DecoderTarget target);

  DecodedPacket decode(const PacketView& packet, std::int64_t t0_ns,
                       std::span<Point, kMaxPointsPerPacket> out, FilterCounts& filtered) const {
    if (simd_kernel_ != nullptr) {
      return simd_kernel_(*simd_tables_, packet, t0_ns, out.data(), filtered);
    }
    return scalar_.decode(packet, t0_ns, out, filtered);
  }

  DecoderTarget target() const noexcept { return target_; }
  const ScalarDecoder& scalar() const noexcept { return scalar_; }

 private:
  ScalarDecoder scalar_;
  DecoderTarget target_;
  SimdKernel simd_kernel_ = nullptr;
  // Owned on the heap at construction (the tables are ~11 KB and 64-byte aligned), never in the
  // hot path.
  std::unique_ptr<SimdDecoderTables> simd_tables_;
};

}  // namespace pandarcap
