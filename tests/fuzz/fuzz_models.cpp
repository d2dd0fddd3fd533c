// Fuzz target: the packet parsers of every supported model (issue 39), one payload at a time and
// as a stream. The first byte chooses the model and the mode:
//   - raw (bit 7 clear): the rest is one payload, given to every model's validate() and to
//     detect_model() / identify_model(), then to the chosen model's stream decoder;
//   - patched (bit 7 set): a valid simulated packet of the model (core/sim/any_model_sensor.hpp),
//     then records of 3 bytes (u16 offset, value) each patching the next packet of the stream:
//     mostly-valid packets that reach the decoder, the outlier rule and the frame assembler.
// Invariants: nothing reads outside the payload (ASan); a model detect_model() names accepts the
// payload itself; packets = accepted + rejected + duplicates; every channel slot of an accepted
// packet is a point or a filtered count; no frame exceeds its capacity.
#include <array>
#include <cstdint>
#include <cstdlib>
#include <span>
#include <vector>

#include "core/decode/any_stream_decoder.hpp"
#include "core/decode/calibration.hpp"
#include "core/frames/frame_collector.hpp"
#include "core/sensors/model_detection.hpp"
#include "core/sensors/sensor_models.hpp"
#include "core/sim/any_model_sensor.hpp"

using namespace pandarcap;

namespace {

constexpr std::size_t kFrameCapacity = 20'000;  // small: frames overflow and the pool runs dry

RejectReason validate_as(SensorModelId id, std::span<const std::uint8_t> p) {
  return with_model(id, [&]<class M>(std::type_identity<M>) { return M::validate(p); });
}

std::uint64_t slots(SensorModelId id) {
  return with_model(id, []<class M>(std::type_identity<M>) {
    return static_cast<std::uint64_t>(M::kBlocks * M::kChannels);
  });
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  const SensorModelId model = kSensorModelIds[data[0] % kSensorModelIds.size()];
  const bool patched = (data[0] & 0x80) != 0;
  bool broken = false;
  FrameCollector collector(3, kFrameCapacity, [&](const Frame& frame) {
    if (frame.size > kFrameCapacity) broken = true;
  });
  AnyStreamDecoder decoder(model, Calibration::nominal(model), {}, collector);

  if (!patched) {
    const std::span<const std::uint8_t> payload(data + 1, size - 1);
    for (const SensorModelId id : kSensorModelIds)
      (void)validate_as(id, payload);
    const DetectedModel detected = detect_model(payload);
    if (detected.kind == DetectionKind::kKnown &&
        validate_as(detected.model, payload) != RejectReason::kNone) {
      std::abort();
    }
    (void)identify_model(payload);
    decoder.process(payload);
  } else {
    ModelSensorConfig config;
    config.udp_sequence = true;
    AnyModelSensor sensor(model, config);
    std::array<std::uint8_t, kLargestDatagramBytes> packet{};
    for (std::size_t at = 1; at + 3 <= size; at += 3) {
      const std::size_t length = sensor.next(packet);
      const std::size_t offset = static_cast<std::size_t>(data[at] | data[at + 1] << 8) % length;
      packet[offset] = data[at + 2];
      decoder.process(std::span<const std::uint8_t>(packet.data(), length));
    }
  }
  decoder.flush();
  const StreamStats& stats = decoder.stats();
  if (broken || stats.packets != stats.accepted + stats.rejected() + stats.duplicates) std::abort();
  if (stats.points + stats.filtered.total() != stats.accepted * slots(model)) std::abort();
  return 0;
}
