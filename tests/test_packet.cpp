// Packet validation (one crafted packet per reject reason) and tail decoding.
#include <catch2/catch.hpp>
#include <vector>

#include "core/sensors/packet.hpp"
#include "core/sim/packet_builder.hpp"
#include "core/sim/synthetic_sensor.hpp"
#include "daemon/pcap/capture_reader.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;

namespace {

std::vector<std::uint8_t> valid_packet(bool with_sequence = false) {
  SyntheticSensorConfig config;
  config.udp_sequence = with_sequence;
  SyntheticSensor sensor(config);
  std::array<std::uint8_t, kMaxPacketBytes> buffer{};
  const std::size_t size = sensor.next(buffer);
  return {buffer.begin(), buffer.begin() + static_cast<std::ptrdiff_t>(size)};
}

}  // namespace

TEST_CASE("a generated packet is valid in both sizes", "[packet]") {
  CHECK(valid_packet(false).size() == 1262);
  CHECK(valid_packet(true).size() == 1266);
  CHECK(validate(valid_packet(false)) == RejectReason::kNone);
  CHECK(validate(valid_packet(true)) == RejectReason::kNone);
}

TEST_CASE("every length other than 1262 and 1266 is rejected as bad_length", "[packet]") {
  const std::vector<std::uint8_t> good = valid_packet(true);
  for (std::size_t size : {0, 1, 124, 512, 1240, 1256, 1261, 1263, 1264, 1265, 1267, 1500, 65507}) {
    std::vector<std::uint8_t> bytes(size, 0);
    std::copy_n(good.begin(), std::min(size, good.size()), bytes.begin());
    INFO("size " << size);
    CHECK(validate(bytes) == RejectReason::kBadLength);
    CHECK_FALSE(PacketView::make(bytes).has_value());
  }
}

TEST_CASE("a bad marker in any block is rejected", "[packet]") {
  for (int b = 0; b < kBlocks; ++b) {
    for (int byte = 0; byte < 2; ++byte) {
      std::vector<std::uint8_t> bytes = valid_packet();
      bytes[kBlockBytes * b + byte] ^= 0x01;
      INFO("block " << b << " byte " << byte);
      CHECK(validate(bytes) == RejectReason::kBadMarker);
    }
  }
  // Newer Hesai models write EE FF; the 40P writes FF EE. The swapped order must not pass.
  std::vector<std::uint8_t> swapped = valid_packet();
  for (int b = 0; b < kBlocks; ++b)
    std::swap(swapped[kBlockBytes * b], swapped[kBlockBytes * b + 1]);
  CHECK(validate(swapped) == RejectReason::kBadMarker);
}

TEST_CASE("azimuth 36000 or above in any block is rejected, 35999 is accepted", "[packet]") {
  for (int b = 0; b < kBlocks; ++b) {
    std::vector<std::uint8_t> bytes = valid_packet();
    for (std::uint16_t azimuth : {std::uint16_t{36000}, std::uint16_t{65535}}) {
      bytes[kBlockBytes * b + 2] = static_cast<std::uint8_t>(azimuth);
      bytes[kBlockBytes * b + 3] = static_cast<std::uint8_t>(azimuth >> 8);
      CHECK(validate(bytes) == RejectReason::kBadAzimuth);
    }
    bytes[kBlockBytes * b + 2] = static_cast<std::uint8_t>(35999);
    bytes[kBlockBytes * b + 3] = static_cast<std::uint8_t>(35999 >> 8);
    CHECK(validate(bytes) == RejectReason::kNone);
  }
}

TEST_CASE("unknown return modes are rejected, the three known ones accepted", "[packet]") {
  std::vector<std::uint8_t> bytes = valid_packet();
  for (int mode = 0; mode < 256; ++mode) {
    bytes[1254] = static_cast<std::uint8_t>(mode);
    const bool known = mode == 0x37 || mode == 0x38 || mode == 0x39;
    INFO("mode " << mode);
    CHECK(validate(bytes) == (known ? RejectReason::kNone : RejectReason::kBadReturnMode));
  }
}

TEST_CASE("all-zero and all-0xFF payloads are rejected without reading past them", "[packet]") {
  CHECK(validate(std::vector<std::uint8_t>(1262, 0x00)) == RejectReason::kBadMarker);
  CHECK(validate(std::vector<std::uint8_t>(1262, 0xFF)) == RejectReason::kBadMarker);
  CHECK(validate(std::span<const std::uint8_t>{}) == RejectReason::kBadLength);
}

TEST_CASE("reject reasons have distinct stable names", "[packet]") {
  CHECK(to_string(RejectReason::kBadLength) == "bad_length");
  CHECK(to_string(RejectReason::kBadMarker) == "bad_marker");
  CHECK(to_string(RejectReason::kBadAzimuth) == "bad_azimuth");
  CHECK(to_string(RejectReason::kBadReturnMode) == "bad_return_mode");
}

TEST_CASE("an encoded tail decodes to the same fields", "[packet]") {
  PacketContents contents;
  contents.azimuth_cdeg.fill(12345);
  contents.distance_raw[3][17] = 0xBEEF;
  contents.reflectivity[3][17] = 0xA5;
  Tail& t = contents.tail;
  t.status_value = 0x2E34;
  t.status_id = 9;
  t.reserved_opaque[0] = 0x43;
  t.reserved_opaque[1] = 0x41;
  t.high_temperature = true;
  t.error_code = 0x0102;
  t.motor_rpm = 1199;
  t.timestamp_us = 999'910;
  t.return_mode_byte = 0x37;
  t.factory = 0x43;
  t.utc = {24, 2, 29, 23, 59, 58};
  t.sequence = 0xFFFFFFFE;
  std::array<std::uint8_t, kMaxPacketBytes> buffer{};
  const std::size_t size = encode(contents, buffer);
  REQUIRE(size == 1266);
  const auto view = PacketView::make(std::span(buffer).first(size));
  REQUIRE(view.has_value());
  const Tail decoded = view->tail();
  CHECK(decoded.status_value == 0x2E34);
  CHECK(decoded.status_id == 9);
  CHECK(decoded.reserved_opaque[0] == 0x43);
  CHECK(decoded.reserved_opaque[1] == 0x41);
  CHECK(decoded.high_temperature);
  CHECK(decoded.error_code == 0x0102);
  CHECK(decoded.motor_rpm == 1199);
  CHECK(decoded.timestamp_us == 999'910);
  CHECK(decoded.return_mode_byte == 0x37);
  CHECK(view->return_mode() == ReturnMode::kStrongest);
  CHECK(decoded.factory == 0x43);
  CHECK(decoded.utc == TailDateTime{24, 2, 29, 23, 59, 58});
  CHECK(decoded.sequence == std::optional<std::uint32_t>(0xFFFFFFFE));
  CHECK(view->distance_raw(3, 17) == 0xBEEF);
  CHECK(view->reflectivity(3, 17) == 0xA5);
  CHECK(view->azimuth_cdeg(9) == 12345);
  // The tail sits at fixed offsets: motor speed at payload byte 1248, little-endian.
  CHECK(buffer[1248] == (1199 & 0xFF));
  CHECK(buffer[1249] == (1199 >> 8));
}

TEST_CASE("the real 1266-byte packet's tail decodes as the spec reads it", "[packet][real]") {
  const auto path = test::real_capture("velocityreport_pandar40p_single_packet_1266B.pcapng");
  if (!path) return;
  CaptureReader reader(path->string());
  CaptureRecord record;
  REQUIRE(reader.next(record) == CaptureStatus::kRecord);
  const auto view = PacketView::make(record.payload);
  REQUIRE(view.has_value());
  const Tail tail = view->tail();
  // Expected values read off the raw bytes of the tail:
  // 36 38 13 79 76 00 00 00 57 02 d6 b4 0d 00 38 42 11 09 06 0e 21 26 | 74 22 04 00
  CHECK(tail.status_value == 0x3836);
  CHECK(tail.status_id == 0x13);
  CHECK(tail.reserved_opaque[0] == 0x79);
  CHECK(tail.reserved_opaque[1] == 0x76);
  CHECK_FALSE(tail.high_temperature);
  CHECK(tail.error_code == 0);
  CHECK(tail.motor_rpm == 599);  // plain RPM: 0x0257
  CHECK(tail.timestamp_us == 0x000DB4D6);
  CHECK(view->return_mode() == ReturnMode::kLast);
  CHECK(tail.factory == 0x42);
  CHECK(tail.utc == TailDateTime{17, 9, 6, 14, 33, 38});
  CHECK(tail.sequence == std::optional<std::uint32_t>(0x00042274));
  CHECK(view->azimuth_cdeg(0) == 11666);
  CHECK(view->azimuth_cdeg(9) == 11846);
  CHECK(view->distance_raw(0, 0) == 1019);
  CHECK(view->reflectivity(0, 0) == 80);
}
