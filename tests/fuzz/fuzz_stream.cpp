// Fuzz target: the frame assembler fed a packet sequence, through the whole StreamDecoder.
// The input is a list of 8-byte records, each turning a valid template packet into the next one
// of the stream: block azimuths (start and step, possibly invalid), the microsecond timestamp,
// the return mode and the UDP sequence. That keeps most packets valid, so the fuzzer explores
// cuts, wraps, gaps, reordering, discontinuities, frame overflow and the accounting rather than
// the validator. Invariants: packets = accepted + rejected + duplicates (a record that repeats
// the one before it makes a duplicate); every channel slot of an accepted packet is a point or a
// filtered count (placed, an outlier, or standing); no frame exceeds its capacity; the frames
// handed out are in sequence order.
#include <array>
#include <cstdint>
#include <cstdlib>

#include "core/decode/calibration.hpp"
#include "core/decode/stream_decoder.hpp"
#include "core/frames/frame_collector.hpp"
#include "core/sensors/packet.hpp"
#include "core/sim/synthetic_sensor.hpp"

using namespace pandarcap;

namespace {

constexpr std::size_t kRecordBytes = 8;
constexpr std::size_t kFrameCapacity = 8'000;  // small: frames overflow and the pool runs dry

std::array<std::uint8_t, kMaxPacketBytes> make_template() {
  SyntheticSensorConfig config;
  config.udp_sequence = true;
  SyntheticSensor sensor(config);
  std::array<std::uint8_t, kMaxPacketBytes> packet{};
  sensor.next(packet);
  return packet;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const Calibration calibration = Calibration::nominal();
  static const std::array<std::uint8_t, kMaxPacketBytes> kTemplate = make_template();
  std::uint64_t last_sequence = 0;
  bool any_frame = false;
  bool broken = false;
  FrameCollector collector(3, kFrameCapacity, [&](const Frame& frame) {
    if (frame.size > kFrameCapacity) broken = true;
    if (any_frame && frame.info.sequence < last_sequence) broken = true;
    last_sequence = frame.info.sequence;
    any_frame = true;
  });
  StreamDecoderConfig config;
  config.cut_angle_deg = data != nullptr && size > 0 ? data[0] % 36 * 10.0 : 0.0;
  StreamDecoder decoder(calibration, config, collector);

  std::array<std::uint8_t, kMaxPacketBytes> packet = kTemplate;
  std::uint32_t microseconds = 0;
  for (std::size_t at = 1; at + kRecordBytes <= size; at += kRecordBytes) {
    const std::uint8_t* r = data + at;
    const std::uint16_t start = static_cast<std::uint16_t>(r[0] | r[1] << 8);
    const int step = static_cast<std::int8_t>(r[2]);
    for (int b = 0; b < kBlocks; ++b) {
      // Mostly in range; values >= 36000 test the validator's azimuth check too.
      const auto azimuth = static_cast<std::uint16_t>((start + b / 2 * step * 10) % 40000);
      packet[kBlockBytes * b + 2] = static_cast<std::uint8_t>(azimuth);
      packet[kBlockBytes * b + 3] = static_cast<std::uint8_t>(azimuth >> 8);
    }
    microseconds += static_cast<std::uint32_t>(r[3] | r[4] << 8) * 4;  // up to ~262 ms a packet
    if (microseconds >= 1'000'000) microseconds -= 1'000'000;
    for (int i = 0; i < 4; ++i)
      packet[kBodyBytes + 10 + i] = static_cast<std::uint8_t>(microseconds >> (8 * i));
    packet[kBodyBytes + 14] = static_cast<std::uint8_t>(0x37 + r[5] % 4);  // 0x3A: invalid
    packet[kPacketBytes] = r[6];
    packet[kPacketBytes + 1] = r[7];
    const std::size_t length = r[7] & 0x80 ? kPacketBytes : kPacketWithSequenceBytes;
    decoder.process(std::span<const std::uint8_t>(packet.data(), length));
  }
  decoder.flush();
  const StreamStats& stats = decoder.stats();
  if (broken || stats.packets != stats.accepted + stats.rejected() + stats.duplicates) std::abort();
  if (stats.points + stats.filtered.total() != stats.accepted * kBlocks * kChannels) std::abort();
  return 0;
}
