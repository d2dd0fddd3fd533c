// PTC on bytes (core/ptc): the framing against the fact sheet's examples, every header problem,
// and the three payload layouts field by field, shorter (an error), longer (parsed, extra
// counted) and with hostile strings.
#include <fmt/format.h>

#include <catch2/catch.hpp>
#include <numeric>
#include <vector>

#include "core/ptc/ptc_messages.hpp"
#include "core/ptc/ptc_protocol.hpp"
#include "core/sim/simulated_unit.hpp"

using namespace pandarcap;
using namespace pandarcap::ptc;

namespace {

std::array<std::uint8_t, kHeaderBytes> bytes8(std::initializer_list<int> values) {
  std::array<std::uint8_t, kHeaderBytes> out{};
  std::size_t i = 0;
  for (const int v : values)
    out[i++] = static_cast<std::uint8_t>(v);
  return out;
}

std::vector<std::uint8_t> counting(std::size_t size) {
  std::vector<std::uint8_t> out(size);
  std::iota(out.begin(), out.end(), std::uint8_t{1});
  return out;
}

}  // namespace

TEST_CASE("PTC request headers are the fact sheet's bytes", "[ptc]") {
  CHECK(request_header(Command::kGetCalibration, 0) ==
        bytes8({0x47, 0x74, 0x05, 0x00, 0x00, 0x00, 0x00, 0x00}));
  CHECK(encode_header(Command::kGetCalibration, 0, 1500) ==
        bytes8({0x47, 0x74, 0x05, 0x00, 0x00, 0x00, 0x05, 0xDC}));
  CHECK(request_header(Command::kPtpDiagnostics, 1) ==
        bytes8({0x47, 0x74, 0x06, 0x00, 0x00, 0x00, 0x00, 0x01}));
  const auto big = encode_header(Command::kGetStatus, 0x07, 0x01020304);
  const ResponseHeader h = decode_header(big);
  CHECK(h.command == 0x09);
  CHECK(h.return_code == 0x07);
  CHECK(h.payload_length == 0x01020304u);
}

TEST_CASE("PTC response headers are checked for magic, command and length", "[ptc]") {
  const auto check = [](std::array<std::uint8_t, kHeaderBytes> b, std::uint32_t max = 4096) {
    return check_response_header(decode_header(b), b, Command::kGetCalibration, max);
  };
  CHECK_FALSE(check(bytes8({0x47, 0x74, 0x05, 0x00, 0x00, 0x00, 0x05, 0xDC})));
  // A non-zero return code is not a header problem: its payload is still read.
  CHECK_FALSE(check(bytes8({0x47, 0x74, 0x05, 0x03, 0x00, 0x00, 0x00, 0x00})));

  const auto magic = check(bytes8({'H', 'T', 'T', 'P', '/', '1', '.', '1'}));
  REQUIRE(magic);
  CHECK(magic->kind == ErrorKind::kBadMagic);
  CHECK_THAT(magic->message, Catch::Contains("48 54"));

  const auto other = check(bytes8({0x47, 0x74, 0x09, 0x00, 0x00, 0x00, 0x00, 0x36}));
  REQUIRE(other);
  CHECK(other->kind == ErrorKind::kUnrelatedResponse);
  CHECK_THAT(other->message, Catch::Contains("0x09") && Catch::Contains("0x05"));

  const auto huge = check(bytes8({0x47, 0x74, 0x05, 0x00, 0xFF, 0xFF, 0xFF, 0xFF}));
  REQUIRE(huge);
  CHECK(huge->kind == ErrorKind::kOversize);
  CHECK_THAT(huge->message, Catch::Contains("4294967295"));
  // Exactly at the bound is accepted, one past it is not.
  CHECK_FALSE(check(bytes8({0x47, 0x74, 0x05, 0x00, 0x00, 0x00, 0x10, 0x00}), 4096));
  CHECK(check(bytes8({0x47, 0x74, 0x05, 0x00, 0x00, 0x00, 0x10, 0x01}), 4096));
}

TEST_CASE("PTC return codes and error kinds have names", "[ptc]") {
  CHECK(describe_return_code(0x00) == "no error");
  CHECK(describe_return_code(0x05) == "unsupported command");
  CHECK(describe_return_code(0x07) == "other error");
  CHECK(describe_return_code(0x08) == "unknown return code");
  CHECK(describe_return_code(0xFF) == "unknown return code");
  for (std::size_t k = 0; k < kErrorKindCount; ++k)
    CHECK(to_string(static_cast<ErrorKind>(k)) != "unknown");
}

TEST_CASE("PTC status payload: every field at its offset", "[ptc]") {
  std::vector<std::uint8_t> p(kStatusBytes, 0);
  p[0] = 0x00, p[1] = 0x01, p[2] = 0x51, p[3] = 0x80;  // 86400 s
  p[4] = 0x02, p[5] = 0x58;                            // 600 RPM
  // T1 = 41.23 °C = 4123 = 0x0000101B; RT5 = -5.00 °C = -500 = 0xFFFFFE0C
  p[6] = 0x00, p[7] = 0x00, p[8] = 0x10, p[9] = 0x1B;
  p[34] = 0xFF, p[35] = 0xFF, p[36] = 0xFE, p[37] = 0x0C;
  p[38] = 1, p[39] = 0;
  p[43] = 7;                   // start-ups
  p[46] = 0x01, p[47] = 0x00;  // 256 min
  p[48] = 2;                   // locked
  const Parsed<SensorStatus> parsed = parse_status(p);
  REQUIRE(parsed.value);
  const SensorStatus& s = *parsed.value;
  CHECK(parsed.extra_bytes == 0);
  CHECK(s.uptime_s == 86400);
  CHECK(s.motor_rpm == 600);
  CHECK(s.temperature_centi_c[0] == 4123);
  CHECK(s.temperature_centi_c[7] == -500);
  CHECK(s.gps_pps_locked == 1);
  CHECK(s.gps_nmea_locked == 0);
  CHECK(s.startup_count == 7);
  CHECK(s.operation_minutes == 256);
  CHECK(ptp_state_name(s.ptp_state) == "locked");
  CHECK(encode_status(s) == p);
  CHECK(ptp_state_name(0) == "free_run");
  CHECK(ptp_state_name(1) == "tracking");
  CHECK(ptp_state_name(3) == "frozen");
  CHECK(ptp_state_name(9) == "unknown");
}

TEST_CASE("PTC payloads shorter than their layout are errors, longer ones parse", "[ptc]") {
  for (std::size_t size = 0; size < kStatusBytes; ++size) {
    const Parsed<SensorStatus> parsed = parse_status(counting(size));
    CHECK_FALSE(parsed.value);
    CHECK(parsed.error == fmt::format("status: {} bytes, expected 54", size));
  }
  CHECK_FALSE(parse_inventory(counting(kInventoryBytes - 1)).value);
  CHECK_FALSE(parse_settings(counting(kConfigBytes - 1)).value);

  const Parsed<SensorStatus> longer = parse_status(counting(kStatusBytes + 6));
  REQUIRE(longer.value);
  CHECK(longer.extra_bytes == 6);
  CHECK(longer.value->uptime_s == 0x01020304u);  // the known fields are where they were
  const Parsed<SensorSettings> settings = parse_settings(counting(kConfigBytes + 9));
  REQUIRE(settings.value);
  CHECK(settings.extra_bytes == 9);
  CHECK(settings.value->data_port == 0x1112);  // bytes 16, 17 = 17, 18
}

TEST_CASE("PTC inventory strings are bounded by their fields and made printable", "[ptc]") {
  std::vector<std::uint8_t> p(kInventoryBytes, 0);
  // The serial fills its 18 bytes with no NUL: read as exactly 18 characters, not into the date.
  for (std::size_t i = 0; i < 18; ++i)
    p[i] = static_cast<std::uint8_t>('A' + i);
  const std::string date = "2019-03-04";
  std::copy(date.begin(), date.end(), p.begin() + 18);
  p[40] = 'v', p[41] = '1', p[42] = 0x1B, p[43] = '\n', p[44] = 0x00, p[45] = 'X';  // ESC, LF
  p[88] = 0xFF, p[89] = '2';
  p[104] = 0xFF, p[105] = 0xFE;  // zero-angle offset -2
  p[108] = 40;
  const Parsed<SensorInventory> parsed = parse_inventory(p);
  REQUIRE(parsed.value);
  const SensorInventory& v = *parsed.value;
  CHECK(v.serial == "ABCDEFGHIJKLMNOPQR");
  CHECK(v.manufacture_date == date);
  CHECK(v.software_version == "v1??");  // control characters replaced, cut at the NUL
  CHECK(v.sensor_firmware == "?2");
  CHECK(v.zero_angle_offset == -2);
  CHECK(v.lines == 40);
}

TEST_CASE("PTC payloads round-trip through encode and parse", "[ptc]") {
  const SimulatedUnit unit = simulated_unit(1200, 0x37, true, 2370);
  const auto inventory = parse_inventory(encode_inventory(unit.inventory));
  REQUIRE(inventory.value);
  CHECK(inventory.value->serial == unit.inventory.serial);
  CHECK(inventory.value->sensor_firmware == unit.inventory.sensor_firmware);
  CHECK(inventory.value->mac == unit.inventory.mac);
  CHECK(mac_text(inventory.value->mac) == "02:50:43:00:00:01");

  const auto settings = parse_settings(encode_settings(unit.settings));
  REQUIRE(settings.value);
  CHECK(settings.value->spin_rate_rpm == 1200);
  CHECK(settings.value->return_mode == 0x37);
  CHECK(settings.value->udp_sequence == 1);
  CHECK(settings.value->data_port == 2370);
  CHECK(clock_source_name(settings.value->clock_source) == "ptp");
  CHECK(ipv4_text(settings.value->destination_ip) == "127.0.0.1");

  const auto status = parse_status(encode_status(unit.status(3601)));
  REQUIRE(status.value);
  CHECK(status.value->uptime_s == 3601);
  CHECK(status.value->motor_rpm == 1200);
  CHECK(status.value->temperature_centi_c == unit.status(3601).temperature_centi_c);
}

TEST_CASE("the simulated unit's calibration differs from the nominal table within bounds",
          "[ptc][calibration]") {
  const Calibration unit = simulated_unit().calibration;
  const Calibration nominal = Calibration::nominal();
  int differing = 0;
  for (int c = 0; c < kChannels; ++c) {
    const double de = unit.elevation_deg[c] - nominal.elevation_deg[c];
    const double da = unit.azimuth_offset_deg[c] - nominal.azimuth_offset_deg[c];
    CHECK(std::abs(de) <= 0.4005);
    CHECK(std::abs(da) <= 0.2005);
    if (std::abs(de) > 0.01) ++differing;
  }
  CHECK(differing >= 35);
  // Served as CSV, it parses back to the same angles (three decimals by construction).
  const Calibration again = Calibration::parse(unit.to_csv(), "served");
  CHECK(again.elevation_deg == unit.elevation_deg);
  CHECK(again.azimuth_offset_deg == unit.azimuth_offset_deg);
}

TEST_CASE("PTC PTP diagnostics: a 64-bit signed offset, then state and elapsed time", "[ptc]") {
  const ptc::PtpDiagnostics ptp{-2'500'000'000'123, 2, 86'400'000};
  const std::vector<std::uint8_t> bytes = encode_ptp_status(ptp);
  REQUIRE(bytes.size() == kPtpStatusBytes);
  CHECK(bytes[0] == 0xFF);  // the offset's high byte: negative, big-endian
  const auto parsed = parse_ptp_status(bytes);
  REQUIRE(parsed.value);
  CHECK(parsed.value->master_offset_ns == -2'500'000'000'123);
  CHECK(parsed.value->state == 2);
  CHECK(parsed.value->elapsed_ms == 86'400'000);
  CHECK_FALSE(parse_ptp_status(std::vector<std::uint8_t>(15)).value);
}
