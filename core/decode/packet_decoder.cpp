#include "core/decode/packet_decoder.hpp"

#include <stdexcept>
#include <string>

namespace pandarcap {

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
