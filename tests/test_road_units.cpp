// Unit tests of the "on the road" features, pure logic only (no thread, socket or child): the
// sensor status's physical ranges (core/ptc/status_plausibility.hpp), how the health renderings
// and the health policy treat an implausible status, control characters in log text
// (core/log_text.hpp), and the bench generator's synthetic source, whose clock must keep running
// across the end of its packet list (bench/udp_traffic.hpp).
#include <catch2/catch.hpp>
#include <cstdint>
#include <cstdlib>
#include <map>
#include <nlohmann/json.hpp>
#include <string>

#include "bench/udp_traffic.hpp"
#include "core/decode/packet_time.hpp"
#include "core/health/health_format.hpp"
#include "core/health/health_policy.hpp"
#include "core/log_text.hpp"
#include "core/ptc/status_plausibility.hpp"
#include "core/sensors/packet.hpp"
#include "core/sensors/timing.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;

namespace {

// A status a healthy Pandar40P sends: every field well inside its range.
ptc::SensorStatus healthy_status() {
  ptc::SensorStatus s;
  s.uptime_s = 86'400;
  s.motor_rpm = 600;
  s.temperature_centi_c.fill(4'050);  // 40.50 °C
  s.gps_pps_locked = 1;
  s.gps_nmea_locked = 1;
  s.ptp_state = 2;  // locked
  return s;
}

std::uint32_t bit(std::uint32_t b) {
  return 1u << b;
}

// A fresh, polled status in the health gauges, filled as daemon/output/health_publisher.cpp does.
SensorStatusGauges status_gauges(const ptc::SensorStatus& s) {
  SensorStatusGauges st;
  st.polled = st.available = true;
  st.interval_seconds = 5;
  st.age_seconds = 1;
  set_status_fields(st, s);
  return st;
}

// A sensor streaming as expected (600 RPM, last return), as tests/test_health_policy.cpp drives it.
HealthGauges road_streaming() {
  HealthGauges g;
  g.return_mode = "last";
  g.rpm_tail = 600;
  g.seconds_since_last_packet = 0.01;
  return g;
}

const HealthExpectations kRoadLastExpectations{"last", 600};

}  // namespace

TEST_CASE("Status plausibility: every range holds at its edge and fails one step past it",
          "[road][unit][ptc]") {
  REQUIRE(ptc::implausible_fields(healthy_status()) == 0);
  // The ranges as the header states them, so a changed constant is a visible decision.
  CHECK(ptc::kMaxPlausibleUptimeSeconds == 316'224'000u);  // 10 x 366 days
  using Edit = void (*)(ptc::SensorStatus&);
  struct Case {
    const char* what;
    Edit inside, outside;
    std::uint32_t bit;
  };
  const Case cases[] = {
      {"uptime", [](auto& s) { s.uptime_s = 316'224'000; },
       [](auto& s) { s.uptime_s = 316'224'001; }, ptc::kUptimeBit},
      {"motor", [](auto& s) { s.motor_rpm = 1300; }, [](auto& s) { s.motor_rpm = 1301; },
       ptc::kMotorBit},
      {"motor stopped", [](auto& s) { s.motor_rpm = 0; }, [](auto& s) { s.motor_rpm = 65535; },
       ptc::kMotorBit},
      {"gps pps", [](auto& s) { s.gps_pps_locked = 0; }, [](auto& s) { s.gps_pps_locked = 2; },
       ptc::kGpsPpsBit},
      {"gps nmea", [](auto& s) { s.gps_nmea_locked = 0; }, [](auto& s) { s.gps_nmea_locked = 2; },
       ptc::kGpsNmeaBit},
      {"ptp", [](auto& s) { s.ptp_state = 3; }, [](auto& s) { s.ptp_state = 4; },
       ptc::kPtpStateBit},
  };
  for (const Case& c : cases) {
    INFO(c.what);
    ptc::SensorStatus s = healthy_status();
    c.inside(s);
    CHECK(ptc::implausible_fields(s) == 0);
    c.outside(s);
    CHECK(ptc::implausible_fields(s) == bit(c.bit));
  }
  // Each temperature on its own, at both ends of -60 .. +150 °C.
  for (std::size_t i = 0; i < ptc::kTemperatureCount; ++i) {
    INFO("temperature " << ptc::kTemperatureNames[i]);
    const std::uint32_t b = ptc::kTemperatureBit0 + static_cast<std::uint32_t>(i);
    for (const auto& [inside, outside] : {std::pair{-6'000, -6'001}, std::pair{15'000, 15'001}}) {
      ptc::SensorStatus s = healthy_status();
      s.temperature_centi_c[i] = inside;
      CHECK(ptc::implausible_fields(s) == 0);
      s.temperature_centi_c[i] = outside;
      CHECK(ptc::implausible_fields(s) == bit(b));
    }
  }
}

TEST_CASE("Status plausibility: several bad fields are all marked, described and named",
          "[road][unit][ptc]") {
  ptc::SensorStatus s = healthy_status();
  s.uptime_s = 0xFFFF'FFFF;                // 136 years
  s.motor_rpm = 53'029;                    // garbage in the speed word
  s.temperature_centi_c[0] = -17'123'456;  // bottom_t1
  s.temperature_centi_c[7] = 20'000;       // top_rt5, 200 °C
  s.ptp_state = 7;
  const std::uint32_t fields = ptc::implausible_fields(s);
  CHECK(fields == (bit(ptc::kUptimeBit) | bit(ptc::kMotorBit) | bit(ptc::kTemperatureBit0) |
                   bit(ptc::kTemperatureBit0 + 7) | bit(ptc::kPtpStateBit)));
  std::string what;
  ptc::describe_implausible(s, fields, what);
  CHECK(what ==
        "uptime 136 years (0..10); motor speed 53029 RPM (0..1300); temperature bottom_t1 "
        "-171234.56 °C (-60..150); temperature top_rt5 200.00 °C (-60..150); PTP state 7 (0..3)");
  // Appended after a prefix that ends in a space, without a separator; nothing for no fields.
  ptc::SensorStatus gps = healthy_status();
  gps.gps_pps_locked = 2;
  gps.gps_nmea_locked = 255;
  std::string line = "left out: ";
  ptc::describe_implausible(gps, ptc::implausible_fields(gps), line);
  CHECK(line == "left out: GPS PPS lock byte 2 (0 or 1); GPS NMEA lock byte 255 (0 or 1)");
  std::string none = "x";
  ptc::describe_implausible(s, 0, none);
  CHECK(none == "x");

  const std::map<std::uint32_t, std::string> names = {
      {ptc::kUptimeBit, "uptime_seconds"},
      {ptc::kMotorBit, "motor_rpm"},
      {ptc::kTemperatureBit0, "temperature_bottom_t1"},
      {ptc::kTemperatureBit0 + 2, "temperature_laser_rt_l"},
      {ptc::kTemperatureBit0 + 7, "temperature_top_rt5"},
      {ptc::kGpsPpsBit, "gps_pps_locked"},
      {ptc::kGpsNmeaBit, "gps_nmea_locked"},
      {ptc::kPtpStateBit, "ptp_state"},
      {ptc::kPtpStateBit + 1, "unknown"},
  };
  for (const auto& [b, name] : names) {
    std::string out = "[";
    ptc::append_field_name(b, out);
    CHECK(out == "[" + name);
  }
}

TEST_CASE("Health renderings leave implausible status fields out and name them",
          "[road][unit][health][ptc]") {
  ptc::SensorStatus s = healthy_status();
  s.motor_rpm = 53'029;
  s.temperature_centi_c[2] = -17'123'456;  // laser_rt_l
  s.temperature_centi_c[5] = 4'321;        // top_rt3, plausible: 43.21 °C
  s.ptp_state = 7;
  HealthSnapshot h;
  h.sensor = "road";
  h.gauges.sensor_status = status_gauges(s);
  REQUIRE(h.gauges.sensor_status.implausible != 0);

  const std::string text = to_json_line(h);
  INFO(text);
  const auto record = nlohmann::json::parse(text);
  const auto& st = record.at("sensor_status");
  CHECK_FALSE(st.contains("motor_rpm"));
  CHECK_FALSE(st.contains("ptp_state"));
  CHECK_FALSE(st.at("temperatures_celsius").contains("laser_rt_l"));
  CHECK(st.at("uptime_seconds") == 86'400);
  CHECK(st.at("gps_pps_locked") == true);
  CHECK(st.at("gps_nmea_locked") == true);
  CHECK(st.at("temperatures_celsius").size() == ptc::kTemperatureCount - 1);
  CHECK(st.at("temperatures_celsius").at("bottom_t1") == Approx(40.5));
  CHECK(st.at("temperatures_celsius").at("top_rt3") == Approx(43.21));
  CHECK(st.at("implausible") ==
        nlohmann::json::array({"motor_rpm", "temperature_laser_rt_l", "ptp_state"}));
  // The garbage is in no other key either.
  CHECK(text.find("53029") == std::string::npos);
  CHECK(text.find("171234") == std::string::npos);

  const std::string prom_text = to_prometheus(h);
  const auto prom = test::prom_samples(prom_text);
  const std::string sensor = "sensor=\"road\"";
  CHECK(prom.count("pandarcap_sensor_motor_speed_rpm{" + sensor + "}") == 0);
  CHECK(prom.count("pandarcap_sensor_temperature_celsius{" + sensor + ",board=\"laser_rt_l\"}") ==
        0);
  CHECK(prom_text.find("pandarcap_sensor_ptp_state{") == std::string::npos);
  CHECK(prom_text.find("53029") == std::string::npos);
  CHECK(prom.at("pandarcap_sensor_uptime_seconds{" + sensor + "}") == "86400");
  CHECK(prom.at("pandarcap_sensor_temperature_celsius{" + sensor + ",board=\"top_rt3\"}") ==
        "43.21");
  CHECK(prom.at("pandarcap_sensor_gps_pps_locked{" + sensor + "}") == "1");

  // The control: the same status made plausible has every field and no "implausible" list.
  s = healthy_status();
  h.gauges.sensor_status = status_gauges(s);
  const auto plausible = nlohmann::json::parse(to_json_line(h)).at("sensor_status");
  CHECK_FALSE(plausible.contains("implausible"));
  CHECK(plausible.at("motor_rpm") == 600);
  CHECK(plausible.at("ptp_state") == "locked");
  CHECK(plausible.at("temperatures_celsius").size() == ptc::kTemperatureCount);
  CHECK(
      test::prom_samples(to_prometheus(h)).at("pandarcap_sensor_motor_speed_rpm{" + sensor + "}") ==
      "600");
}

TEST_CASE("Health policy: an implausible status degrades, naming the field and nothing else",
          "[road][unit][health][policy][ptc]") {
  const HealthCounters c;
  HealthGauges g = road_streaming();
  ptc::SensorStatus s = healthy_status();
  s.motor_rpm = 53'029;  // far off 600 too, but not believed: not also a "motor at" problem
  g.sensor_status = status_gauges(s);
  classify_health(c, c, kRoadLastExpectations, false, "", g);
  CHECK(g.state == HealthState::kDegraded);
  CHECK(g.reason == "sensor status implausible: motor speed 53029 RPM (0..1300)");

  // A PTP byte out of range is not "PTP not locked" either, even with PTP as the clock source.
  s = healthy_status();
  s.ptp_state = 9;
  g.sensor_status = status_gauges(s);
  g.sensor_status.clock_source_known = g.sensor_status.clock_source_ptp = true;
  classify_health(c, c, kRoadLastExpectations, false, "", g);
  CHECK(g.state == HealthState::kDegraded);
  CHECK(g.reason == "sensor status implausible: PTP state 9 (0..3)");

  // Stale: its values are not current, so neither is their plausibility.
  g.sensor_status.stale = true;
  g.sensor_status.age_seconds = 16;
  classify_health(c, c, kRoadLastExpectations, false, "", g);
  CHECK(g.reason == "sensor status stale: no answer over PTC for 16 s");

  // The same status, plausible and consistent with the packets: ok.
  g.sensor_status = status_gauges(healthy_status());
  classify_health(c, c, kRoadLastExpectations, false, "", g);
  CHECK(g.state == HealthState::kOk);
  CHECK(g.reason.empty());
}

TEST_CASE("Health policy: the status's motor speed is held to 10 % of the expected RPM",
          "[road][unit][health][policy][ptc]") {
  const HealthCounters c;
  HealthGauges g = road_streaming();  // the tails say 600: only the status can be off
  struct Case {
    std::uint16_t rpm;
    const char* reason;  // "" for ok
  };
  const Case cases[] = {
      {660, ""},
      {661, "sensor status: motor at 661 RPM (expected 600)"},
      {540, ""},
      {539, "sensor status: motor at 539 RPM (expected 600)"},
      {0, "sensor status: motor at 0 RPM (expected 600)"},  // standby: plausible, not expected
  };
  for (const Case& k : cases) {
    INFO(k.rpm);
    ptc::SensorStatus s = healthy_status();
    s.motor_rpm = k.rpm;
    g.sensor_status = status_gauges(s);
    REQUIRE(g.sensor_status.implausible == 0);
    classify_health(c, c, kRoadLastExpectations, false, "", g);
    CHECK(g.state == (*k.reason == '\0' ? HealthState::kOk : HealthState::kDegraded));
    CHECK(g.reason == k.reason);
  }
}

TEST_CASE("Health policy: duplicates, outliers and lost recordings degrade while they grow",
          "[road][unit][health][policy]") {
  struct Case {
    std::uint64_t HealthCounters::*counter;
    const char* reason;
  };
  const Case cases[] = {
      {&HealthCounters::duplicate_packets, "3 duplicate packets"},
      {&HealthCounters::outlier_packets, "3 isolated outlier packets"},
      {&HealthCounters::pcap_packets_lost, "3 recorded packets lost (recording removed)"},
      {&HealthCounters::mcap_messages_lost, "3 MCAP messages lost (file removed)"},
  };
  for (const Case& k : cases) {
    INFO(k.reason);
    HealthCounters before, now;
    before.*k.counter = 5;
    now.*k.counter = 8;
    HealthGauges g = road_streaming();
    classify_health(now, before, kRoadLastExpectations, false, "", g);
    CHECK(g.state == HealthState::kDegraded);
    CHECK(g.reason == k.reason);
    classify_health(now, now, kRoadLastExpectations, false, "", g);
    CHECK(g.state == HealthState::kOk);
  }
}

TEST_CASE("Log text: control characters become hex escapes, everything else is kept",
          "[road][unit][log]") {
  CHECK(escaped_control("out\n[info] ok") == "out\\x0a[info] ok");
  CHECK(escaped_control("a\rb\tc\x1b[31md\x7f") == "a\\x0db\\x09c\\x1b[31md\\x7f");
  CHECK(escaped_control(std::string("nul\0here", 8)) == "nul\\x00here");
  CHECK(escaped_control(std::string("\x01\x1f", 2)) == "\\x01\\x1f");
  CHECK(escaped_control("").empty());
  std::string printable;
  for (char ch = 0x20; ch < 0x7F; ++ch)
    printable += ch;
  CHECK(escaped_control(printable) == printable);
  const std::string utf8 = "température 40 °C — 日本 😀";
  CHECK(escaped_control(utf8) == utf8);
  // A backslash is kept as it is, so an escaped text escapes to itself.
  CHECK(escaped_control("C:\\dir\\x0a") == "C:\\dir\\x0a");
  const std::string once = escaped_control("x\ny\\z\x1b");
  CHECK(escaped_control(once) == once);
  // Appending keeps what is already there.
  std::string out = "name: ";
  append_escaped_control("a\nb", out);
  CHECK(out == "name: a\\x0ab");
}

TEST_CASE("Bench traffic source: its packet times rise one period at a time, across loops",
          "[road][unit][bench]") {
  for (const auto& [rpm, mode] :
       {std::pair{600, ReturnMode::kDual}, std::pair{1200, ReturnMode::kLast}}) {
    INFO(rpm << " RPM, " << to_string(mode));
    SyntheticSensorConfig config;
    config.rpm = rpm;
    config.return_mode = mode;
    const auto source = bench::TrafficSource::synthetic(config);
    const std::size_t n = source.bodies.size();
    REQUIRE(n == (mode == ReturnMode::kDual ? 3600u : 1800u));
    REQUIRE(source.offsets_ns.size() == n);
    const std::int64_t period = packet_period_ns(mode);

    // The offsets are the times the bodies' own tails carry, from the first's, to the µs
    // (checked in plain code, reported through Catch2 once: 5400 bodies).
    PacketClock clock;
    std::int64_t first_ns = 0;
    std::size_t invalid = 0, off_offsets = 0;
    for (std::size_t k = 0; k < n; ++k) {
      const auto view = PacketView::make(source.bodies[k]);
      const PacketTime t = view ? clock.convert(view->utc(), view->timestamp_us()) : PacketTime{};
      if (!view || !t.valid()) {
        ++invalid;
        continue;
      }
      if (k == 0) first_ns = t.t0_ns;
      if (std::abs(t.t0_ns - first_ns - source.offsets_ns[k]) > 1'000) ++off_offsets;
    }
    CHECK(invalid == 0);
    CHECK(off_offsets == 0);

    // The generator's clock for packet g: loop (g / n) plus the body's offset. Over two and a
    // half loops every step is one packet period, the loop boundaries included.
    const auto time_of = [&](std::size_t g) {
      return static_cast<std::int64_t>(g / n) * source.loop_ns + source.offsets_ns[g % n];
    };
    std::size_t off_steps = 0;
    for (std::size_t g = 1; g < n * 5 / 2; ++g) {
      if (time_of(g) - time_of(g - 1) != period) ++off_steps;
    }
    CHECK(off_steps == 0);
    CHECK(time_of(n) - time_of(n - 1) == period);
  }
}
