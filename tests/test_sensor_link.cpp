// The daemon and pandarcap-ctl talking to a sensor over PTC: the simulated sensor's own
// calibration fetched and used, the sensor's identity and status in the health outputs, the
// fallbacks of calibration_source against sensors that refuse, stay silent or misbehave (with
// capture unaffected), PTP not locked and a status gone stale reaching the health state.
#include <signal.h>

#include <catch2/catch.hpp>
#include <chrono>
#include <cmath>
#include <fstream>
#include <optional>
#include <string_view>

#include "core/decode/decoder.hpp"
#include "core/sim/simulated_unit.hpp"
#include "core/sim/synthetic_sensor.hpp"
#include "daemon/ptc/simulated_ptc_server.hpp"
#include "support/hostile_ptc_server.hpp"
#include "support/live_daemon.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
using namespace std::chrono_literals;

namespace {

double degrees(double radians) {
  return radians * 180.0 / M_PI;
}

// Sends traffic to `daemon` in short bursts, continuing one stream, until `done(last record)`
// or `timeout`: the health state needs packets flowing to say anything but no_data.
template <typename Done>
bool send_until(test::LiveDaemon& daemon, std::uint64_t& sent, Done done,
                std::chrono::seconds timeout = 20s) {
  const auto source = bench::TrafficSource::synthetic(SyntheticSensorConfig{});
  const auto end = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < end) {
    bench::GeneratorOptions burst;
    burst.port = daemon.port;
    burst.rate_pps = 1000;
    burst.seconds = 0.25;
    burst.first_sequence = sent;
    sent += bench::run_generator(source, burst).sent;
    const nlohmann::json record = test::last_health_record(daemon.out);
    if (!record.is_null() && done(record)) return true;
  }
  return false;
}

std::string reason(const nlohmann::json& record) {
  return record.value("reason", "");
}

}  // namespace

TEST_CASE("decoding with the sensor's table differs from nominal exactly as the tables differ",
          "[ptc][calibration]") {
  const Calibration unit = simulated_unit().calibration;
  const Calibration nominal = Calibration::nominal();
  SyntheticSensor sensor(SyntheticSensorConfig{}, unit);  // the room seen through this unit
  const ScalarDecoder with_unit(unit, {});
  const ScalarDecoder with_nominal(nominal, {});
  std::array<std::uint8_t, kMaxPacketBytes> buffer{};
  std::array<Point, kMaxPointsPerPacket> a{}, b{};
  FilterCounts filtered_a, filtered_b;
  double worst_floor_nominal = 0;
  std::size_t floor_points = 0;
  for (int k = 0; k < 360; ++k) {
    const std::size_t size = sensor.next(buffer);
    const auto view = PacketView::make(std::span(buffer).first(size));
    REQUIRE(view);
    const DecodedPacket da = with_unit.decode(*view, 0, a, filtered_a);
    const DecodedPacket db = with_nominal.decode(*view, 0, b, filtered_b);
    REQUIRE(da.point_count == db.point_count);  // angles change where points go, not which
    for (std::size_t i = 0; i < da.point_count; ++i) {
      const Point& p = a[i];
      const Point& q = b[i];
      REQUIRE(p.channel == q.channel);
      CHECK(p.distance_m == q.distance_m);
      const int c = p.channel;
      // Each point's elevation is its table's, so the two differ by the tables' difference.
      const double elevation_p = degrees(std::asin(p.z / p.distance_m));
      const double elevation_q = degrees(std::asin(q.z / q.distance_m));
      CHECK(elevation_p - elevation_q ==
            Approx(unit.elevation_deg[c] - nominal.elevation_deg[c]).margin(2e-3));
      // And the azimuth (0.01° steps) by the offsets' difference.
      const double d_az =
          (static_cast<int>(p.azimuth_cdeg) - q.azimuth_cdeg + 54000) % 36000 - 18000;
      CHECK(d_az / 100.0 ==
            Approx(unit.azimuth_offset_deg[c] - nominal.azimuth_offset_deg[c]).margin(0.011));
      if (p.intensity == 20) {  // the floor: on it with the unit's table, off it with nominal
        CHECK(p.z == Approx(-1.8).margin(0.015));
        worst_floor_nominal = std::max(worst_floor_nominal, std::abs(q.z + 1.8));
        ++floor_points;
      }
    }
  }
  CHECK(floor_points > 1000);
  CHECK(worst_floor_nominal > 0.05);  // nominal angles put floor points centimetres off it
}

TEST_CASE("pandarcapd --simulate decodes with the simulated sensor's own calibration",
          "[ptc][daemon][threads]") {
  test::ScratchDir dir("ptc-simulate");
  const std::filesystem::path out = dir / "out";
  const auto started = std::chrono::steady_clock::now();
  const test::CommandResult run =
      test::run_command(test::pandarcapd_command() +
                        " --simulate --duration 2.5 --status-interval 0.5 --output-dir " +
                        test::quoted(out) + " 2>&1");
  const double ran_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  INFO(run.out);
  REQUIRE(run.exit_code == 0);
  CHECK_THAT(run.out, Catch::Contains("calibration: from sensor (serial PCSIM40P00000001, "
                                      "firmware sim-fw-1.0) at 127.0.0.1:"));
  CHECK_THAT(run.out, Catch::Contains("sensor config: 600 RPM, clock source ptp"));
  // The table the frames were decoded with travels with the recording: the unit's, not nominal.
  CHECK(harness::read_file(out / "raw" / "calibration.csv") ==
        simulated_unit().calibration.to_csv());
  const auto sensor_json = nlohmann::json::parse(harness::read_file(out / "raw" / "sensor.json"));
  CHECK(sensor_json["calibration_source"] == "sensor");
  CHECK(sensor_json["inventory"]["serial"] == "PCSIM40P00000001");
  CHECK(sensor_json["config"]["clock_source"] == "ptp");

  const nlohmann::json last = test::last_health_record(out);
  REQUIRE(!last.is_null());
  CHECK(last["sensor_info"]["calibration_source"] == "sensor");
  CHECK(last["sensor_info"]["serial"] == "PCSIM40P00000001");
  CHECK(last["sensor_info"]["firmware"] == "sim-fw-1.0");
  const nlohmann::json& status = last["sensor_status"];
  CHECK(status["polled"] == true);
  CHECK(status["available"] == true);
  CHECK(status["stale"] == false);
  CHECK(status["ptp_state"] == "locked");
  CHECK(status["clock_source"] == "ptp");
  CHECK(status["motor_rpm"] == 600);
  CHECK(status["temperatures_celsius"]["laser_rt_l"] == Approx(51.2));
  // Calibration, inventory, config at start, then a config and a status per poll.
  CHECK(test::health_counter(last, "ptc_requests") >= 5);
  CHECK(test::health_counter(last, "ptc_errors") == 0);
  // Nothing of the sensor's raises a problem. (A slowed build's simulated sensor, starved on a
  // loaded machine, sends its packets late: the reason may then say its clock is behind the
  // host's, by no more than the run lasted: clock_behind_by_at_most.)
  const std::string said = reason(last);
  INFO("reason: " << said);
  for (const std::string_view part : test::reason_parts(said)) {
    const bool slow_clock = test::kSlowBuild && test::clock_behind_by_at_most(part, ran_s);
    CHECK((part.find("sensor") == std::string_view::npos || slow_clock));
  }
  const std::string prom = harness::read_file(out / "health" / "pandarcap.prom");
  CHECK_THAT(prom, Catch::Contains("pandarcap_sensor_info{sensor=\"pandar40p\",serial="
                                   "\"PCSIM40P00000001\",firmware=\"sim-fw-1.0\","
                                   "calibration_source=\"sensor\"} 1"));
  CHECK_THAT(prom, Catch::Contains("pandarcap_sensor_ptp_state{sensor=\"pandar40p\","
                                   "state=\"locked\"} 1"));
}

TEST_CASE("calibration_source = nominal and file are used as told, the sensor not asked",
          "[ptc][daemon][threads]") {
  test::ScratchDir dir("ptc-sources");
  const std::filesystem::path table = dir / "front.csv";
  Calibration file_table = Calibration::nominal();
  file_table.elevation_deg[0] = 14.5;
  std::ofstream(table) << file_table.to_csv();
  for (const auto& [source, expected] : {std::pair{"nominal", Calibration::nominal().to_csv()},
                                         std::pair{"file", file_table.to_csv()}}) {
    INFO(source);
    const std::filesystem::path out = dir / source;
    const test::CommandResult run = test::run_command(
        test::pandarcapd_command() + " --simulate --duration 1 --calibration-source " + source +
        " --calibration " + test::quoted(table) + " --status-interval 0 --output-dir " +
        test::quoted(out) + " 2>&1");
    INFO(run.out);
    REQUIRE(run.exit_code == 0);
    CHECK(harness::read_file(out / "raw" / "calibration.csv") == expected);
    const nlohmann::json last = test::last_health_record(out);
    CHECK(last["sensor_info"]["calibration_source"] == source);
    CHECK(last["sensor_info"]["serial"] == "");
    CHECK(test::health_counter(last, "ptc_requests") == 0);
    CHECK(last["sensor_status"]["polled"] == false);
  }
}

TEST_CASE(
    "a sensor that accepts and never answers: the daemon falls back to the file and "
    "captures everything",
    "[ptc][daemon][threads]") {
  test::ScratchDir dir("ptc-silent");
  test::HostilePtcServer silent(test::Hostile::kSilent);
  const std::filesystem::path table = dir / "front.csv";
  std::ofstream(table) << simulated_unit().calibration.to_csv();
  test::LiveDaemon daemon(dir, "calibration_source = \"auto\"\ncalibration_file = \"" +
                                   table.string() +
                                   "\"\nptc_port = " + std::to_string(silent.port()) +
                                   "\nptc_timeout_ms = 400\nstatus_interval_seconds = 0.5\n");
  REQUIRE(daemon.ready());
  const std::string log = daemon.process->log();
  CHECK_THAT(log, Catch::Contains("calibration: PTC 127.0.0.1:" + std::to_string(silent.port()) +
                                  " calibration: timed out after 400 ms") &&
                      Catch::Contains("; using calibration_file " + table.string()));
  CHECK_THAT(log, Catch::Contains("calibration: from file " + table.string()));

  bench::GeneratorOptions traffic;
  traffic.rate_pps = 1800;
  traffic.seconds = 1.5;
  const bench::GeneratorResult sent = daemon.send(traffic);
  const nlohmann::json last = daemon.stop_after(sent.sent);
  REQUIRE(daemon.exit_status == 0);
  // Capture went on as if no sensor control port existed.
  CHECK(test::health_counter(last, "packets_accepted") +
            test::health_counter(last, "kernel_drops") +
            test::health_counter(last, "ring_overruns") ==
        sent.sent);
  if (!test::kSlowBuild) CHECK(test::health_counter(last, "packets_accepted") == sent.sent);
  CHECK(test::health_counter(last, "frames_written") > 0);
  CHECK(last["sensor_info"]["calibration_source"] == "file");
  CHECK(test::health_counter(last, "ptc_errors") >= 2);  // the start's and at least one poll's
  CHECK(test::health_counter(last, "ptc_errors") == test::health_counter(last, "ptc_requests"));
  CHECK(last["sensor_status"]["available"] == false);
  CHECK(last["sensor_status"]["age_seconds"] == -1);
  CHECK_THAT(reason(last), !Catch::Contains("sensor"));  // never answered: reported, not degraded
  CHECK(harness::read_file(daemon.out / "raw" / "calibration.csv") ==
        simulated_unit().calibration.to_csv());
  CHECK_THAT(daemon.process->log(), Catch::Contains("sensor status: PTC 127.0.0.1:"));
}

TEST_CASE("calibration_source = sensor with no answer stops the start (exit 69), naming why",
          "[ptc][daemon][threads]") {
  test::ScratchDir dir("ptc-required");
  test::RefusingPort refusing;
  const test::CommandResult run = test::run_command(
      test::pandarcapd_command() + " --host-ip 127.0.0.1 --port " +
      std::to_string(harness::free_udp_port()) +
      " --sensor-ip 127.0.0.1 --calibration-source sensor --ptc-port " +
      std::to_string(refusing.port) + " --output-dir " + test::quoted(dir / "out") + " 2>&1");
  INFO(run.out);
  CHECK(run.exit_code == 69);
  CHECK_THAT(run.out, Catch::Contains("calibration_source = \"sensor\": PTC 127.0.0.1:" +
                                      std::to_string(refusing.port) +
                                      " calibration: cannot connect: Connection refused"));
  CHECK_FALSE(std::filesystem::exists(dir / "out" / "raw"));

  test::HostilePtcServer magic(test::Hostile::kWrongMagic);
  const test::CommandResult wrong = test::run_command(
      test::pandarcapd_command() +
      " --simulate --duration 1 --calibration-source sensor --ptc-port " +
      std::to_string(magic.port()) + " --output-dir " + test::quoted(dir / "out2") + " 2>&1");
  INFO(wrong.out);
  CHECK(wrong.exit_code == 69);
  CHECK_THAT(wrong.out, Catch::Contains("wrong magic bytes 48 54"));

  // A replay has no sensor to ask unless told where it is.
  const test::CommandResult replay = test::run_command(
      test::pandarcapd_command() + " --replay /nonexistent.pcap --calibration-source sensor 2>&1");
  CHECK(replay.exit_code == 69);
  CHECK_THAT(replay.out, Catch::Contains("needs sensor.sensor_ip"));
}

TEST_CASE("PTP not locked degrades the state, a status gone stale too", "[ptc][daemon][threads]") {
  test::ScratchDir dir("ptc-ptp");
  SimulatedUnit unit = simulated_unit();
  unit.ptp_state = static_cast<std::uint8_t>(ptc::PtpState::kTracking);
  unit.answers_ptp_diagnostics = true;
  unit.ptp_offset_ns = -2500;
  std::optional<SimulatedPtcServer> sensor(std::in_place, unit);
  test::LiveDaemon daemon(dir, "ptc_port = " + std::to_string(sensor->port()) +
                                   "\nptc_timeout_ms = 500\nstatus_interval_seconds = 0.3\n");
  REQUIRE(daemon.ready());
  CHECK_THAT(daemon.process->log(), Catch::Contains("calibration: from sensor (serial "));
  std::uint64_t sent = 0;

  const auto tracking = [](const nlohmann::json& r) {
    return r["state"] == "degraded" &&
           reason(r).find("sensor clock source is PTP but PTP is tracking (not locked)") !=
               std::string::npos;
  };
  CHECK(send_until(daemon, sent, tracking));
  const nlohmann::json tracked = test::last_health_record(daemon.out);
  CHECK(tracked["sensor_status"]["ptp_offset_seconds"] == Approx(-2.5e-6));
  // The .prom is put in place by the finisher thread, after the writer's JSON line.
  CHECK(harness::wait_until(
      [&] {
        return harness::read_file(daemon.out / "health" / "pandarcap.prom")
                   .find("state=\"tracking\"} 1") != std::string::npos;
      },
      std::chrono::seconds(5)));

  sensor->set_ptp_state(static_cast<std::uint8_t>(ptc::PtpState::kLocked));
  const auto locked = [](const nlohmann::json& r) {
    return r["sensor_status"].value("ptp_state", "") == "locked" &&
           reason(r).find("PTP") == std::string::npos;
  };
  CHECK(send_until(daemon, sent, locked));

  sensor.reset();  // the control port goes away; packets keep coming
  const auto stale = [](const nlohmann::json& r) {
    return r["sensor_status"]["stale"] == true &&
           reason(r).find("sensor status stale: no answer over PTC for") != std::string::npos;
  };
  CHECK(send_until(daemon, sent, stale));
  const nlohmann::json last = test::last_health_record(daemon.out);
  // A stale status's values are not reported as if fresh.
  CHECK_FALSE(last["sensor_status"].contains("ptp_state"));
  CHECK_FALSE(last["sensor_status"].contains("uptime_seconds"));
  // The .prom of the same second is put in place by the finisher thread, after the JSON line
  // the writer appends: waited for, not assumed.
  const std::filesystem::path prom = daemon.out / "health" / "pandarcap.prom";
  harness::wait_until(
      [&] {
        return harness::read_file(prom).find(
                   "pandarcap_sensor_status_stale{sensor=\"pandar40p\"} 1") != std::string::npos;
      },
      std::chrono::seconds(5));
  CHECK_THAT(harness::read_file(prom),
             Catch::Contains("pandarcap_sensor_status_stale{sensor=\"pandar40p\"} 1") &&
                 !Catch::Contains("pandarcap_sensor_uptime_seconds"));
  CHECK_THAT(daemon.process->log(), Catch::Contains("sensor status: PTC 127.0.0.1:"));
  daemon.stop_after(sent);
  CHECK(daemon.exit_status == 0);
}

TEST_CASE("sensor keys in the configuration are checked with their position", "[ptc][config]") {
  test::ScratchDir dir("ptc-config");
  const auto check = [&](const std::string& toml) {
    std::ofstream(dir / "c.toml") << toml;
    return test::run_command(test::pandarcapd_command() + " --check-config -c " +
                             test::quoted(dir / "c.toml") + " 2>&1");
  };
  const auto file_without = check("[sensor]\ncalibration_source = \"file\"\n");
  CHECK(file_without.exit_code == 78);
  CHECK_THAT(file_without.out, Catch::Contains("c.toml:2:22: sensor.calibration_source: \"file\" "
                                               "needs sensor.calibration_file"));
  const auto bogus = check("[sensor]\n\ncalibration_source = \"vendor\"\n");
  CHECK(bogus.exit_code == 78);
  CHECK_THAT(bogus.out, Catch::Contains("c.toml:3:22: sensor.calibration_source:"));
  const auto port = check("[sensor]\nptc_port = 0\n");
  CHECK(port.exit_code == 78);
  CHECK_THAT(port.out, Catch::Contains("c.toml:2:12: sensor.ptc_port: 0 is out of range"));
  const auto often = check("[sensor]\nstatus_interval_seconds = 0.01\n");
  CHECK(often.exit_code == 78);
  CHECK_THAT(often.out, Catch::Contains("sensor.status_interval_seconds"));
  CHECK(check("[sensor]\ncalibration_source = \"nominal\"\nstatus_interval_seconds = 0\n")
            .exit_code == 0);
}

TEST_CASE("pandarcap-ctl reads the sensor's calibration, inventory, config and status",
          "[ptc][ctl][threads]") {
  SimulatedPtcServer sensor(simulated_unit(1200, 0x37, false, 2368));
  const std::string ctl = test::quoted(test::binary("pandarcap-ctl")) + " 127.0.0.1 --port " +
                          std::to_string(sensor.port());

  const test::CommandResult calibration = test::run_command(ctl + " calibration");
  CHECK(calibration.exit_code == 0);
  // The CSV is what calibration_file accepts, and it is the unit's table.
  const Calibration parsed = Calibration::parse(calibration.out, "pandarcap-ctl");
  CHECK(parsed.elevation_deg == simulated_unit().calibration.elevation_deg);
  CHECK(parsed.azimuth_offset_deg == simulated_unit().calibration.azimuth_offset_deg);

  const test::CommandResult status = test::run_command(ctl + " status --json");
  CHECK(status.exit_code == 0);
  const auto s = nlohmann::json::parse(status.out);
  CHECK(s["motor_rpm"] == 1200);
  CHECK(s["ptp_state"] == "locked");
  CHECK(s["temperatures_celsius"]["bottom_t1"] == Approx(40.12));

  const test::CommandResult inventory = test::run_command(ctl + " inventory");
  CHECK(inventory.exit_code == 0);
  CHECK_THAT(inventory.out, Catch::Contains("PCSIM40P00000001") && Catch::Contains("sim-fw-1.0"));
  const test::CommandResult config = test::run_command(ctl + " config --json");
  CHECK(config.exit_code == 0);
  CHECK(nlohmann::json::parse(config.out)["clock_source"] == "ptp");
  CHECK(nlohmann::json::parse(config.out)["return_mode"] == 0x37);
  CHECK(sensor.requests() == 4);
}

TEST_CASE("pandarcap-ctl fails clearly: usage 64, no answer 69, protocol 76",
          "[ptc][ctl][threads]") {
  const std::string ctl = test::quoted(test::binary("pandarcap-ctl"));
  CHECK(test::run_command(ctl + " --help").exit_code == 0);
  CHECK(test::run_command(ctl + " 2>/dev/null").exit_code == 64);
  CHECK(test::run_command(ctl + " 127.0.0.1 reboot 2>/dev/null").exit_code == 64);
  CHECK(test::run_command(ctl + " sensor.local status 2>/dev/null").exit_code == 64);
  CHECK(test::run_command(ctl + " 127.0.0.1 status --port 70000 2>/dev/null").exit_code == 64);

  test::RefusingPort refusing;
  const auto refused = test::run_command(ctl + " 127.0.0.1 status --port " +
                                         std::to_string(refusing.port) + " 2>&1");
  CHECK(refused.exit_code == 69);
  CHECK_THAT(refused.out, Catch::Contains("Connection refused"));

  test::HostilePtcServer silent(test::Hostile::kSilent);
  const auto timeout = test::run_command(ctl + " 127.0.0.1 status --timeout-ms 300 --port " +
                                         std::to_string(silent.port()) + " 2>&1");
  CHECK(timeout.exit_code == 69);
  CHECK_THAT(timeout.out, Catch::Contains("timed out after 300 ms"));

  test::HostilePtcServer magic(test::Hostile::kWrongMagic);
  const auto protocol = test::run_command(ctl + " 127.0.0.1 inventory --port " +
                                          std::to_string(magic.port()) + " 2>&1");
  CHECK(protocol.exit_code == 76);
  CHECK_THAT(protocol.out, Catch::Contains("not a PTC server"));

  test::HostilePtcServer bad(test::Hostile::kBadCalibration);
  const auto table = test::run_command(ctl + " 127.0.0.1 calibration --port " +
                                       std::to_string(bad.port()) + " 2>&1");
  CHECK(table.exit_code == 76);
  CHECK_THAT(table.out, Catch::Contains("channels missing: 40"));
}
