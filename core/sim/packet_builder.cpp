#include "core/sim/packet_builder.hpp"

namespace pandarcap {

namespace {

void store_u16_le(std::uint8_t* p, std::uint16_t v) {
  p[0] = static_cast<std::uint8_t>(v);
  p[1] = static_cast<std::uint8_t>(v >> 8);
}

void store_u32_le(std::uint8_t* p, std::uint32_t v) {
  for (int i = 0; i < 4; ++i)
    p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}

}  // namespace

std::size_t encode(const PacketContents& contents, std::span<std::uint8_t, kMaxPacketBytes> out) {
  std::uint8_t* p = out.data();
  for (int b = 0; b < kBlocks; ++b) {
    std::uint8_t* block = p + kBlockBytes * b;
    block[0] = kMarker0;
    block[1] = kMarker1;
    store_u16_le(block + 2, contents.azimuth_cdeg[b]);
    for (int c = 0; c < kChannels; ++c) {
      store_u16_le(block + 4 + 3 * c, contents.distance_raw[b][c]);
      block[6 + 3 * c] = contents.reflectivity[b][c];
    }
  }
  const Tail& tail = contents.tail;
  std::uint8_t* t = p + kBodyBytes;
  store_u16_le(t + 0, tail.status_value);
  t[2] = tail.status_id;
  t[3] = tail.reserved_opaque[0];
  t[4] = tail.reserved_opaque[1];
  t[5] = tail.high_temperature ? 1 : 0;
  store_u16_le(t + 6, tail.error_code);
  store_u16_le(t + 8, tail.motor_rpm);
  store_u32_le(t + 10, tail.timestamp_us);
  t[14] = tail.return_mode_byte;
  t[15] = tail.factory;
  t[16] = tail.utc.year_since_2000;
  t[17] = tail.utc.month;
  t[18] = tail.utc.day;
  t[19] = tail.utc.hour;
  t[20] = tail.utc.minute;
  t[21] = tail.utc.second;
  if (!tail.sequence) return kPacketBytes;
  store_u32_le(p + kPacketBytes, *tail.sequence);
  return kPacketWithSequenceBytes;
}

}  // namespace pandarcap
