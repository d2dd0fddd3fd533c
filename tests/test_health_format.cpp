// The health renderings: Prometheus text (node_exporter textfile conventions, checked with
// promtool when it is installed) and the JSON line (every counter present under its field name).
#include <catch2/catch.hpp>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <regex>
#include <sstream>

#include "core/health/health_format.hpp"
#include "core/text_encoding.hpp"
#include "core/utc_time.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;

namespace {

// A snapshot where every counter has a distinct value, so a field rendered from the wrong
// member shows up as a wrong number.
HealthSnapshot distinct_snapshot() {
  HealthSnapshot h;
  h.unix_time_ns = 1'700'000'000'123'456'789;
  h.sensor = "front \"left\"\\lidar";
  h.version = "1.2.3";
  h.decoder = "avx2";
  for (int i = 0; i < 100; ++i)
    h.latency.record(100'000 + i * 1000);  // 100 .. 199 µs
  h.latency.record(3'000'000);             // one 3 ms outlier
  h.hot_path_allocations = HotPathAllocations{0, 0, 7};
  HealthCounters& c = h.counters;
  std::uint64_t v = 1000;
#define PANDARCAP_FIELD_ADDRESS(field, prometheus_name, help) &c.field,
  for (std::uint64_t* field : {PANDARCAP_HEALTH_COUNTERS(PANDARCAP_FIELD_ADDRESS)}) {
#undef PANDARCAP_FIELD_ADDRESS
    *field = v++;
  }
  for (std::size_t i = 0; i < kRejectReasonCount; ++i)
    c.rejects[i] = 10 + i;
  c.packets_rejected = 11 + 12 + 13 + 14;
  c.file_create_cpu_us = 1'234'567;
  for (std::size_t i = 0; i < kFilterReasonCount; ++i)
    c.filtered_points[i] = 20 + i;
  h.gauges.rpm_tail = 600;
  h.gauges.rpm_measured = 599.5;
  h.gauges.frame_rate_hz = 10;
  h.gauges.return_mode = "dual";
  h.gauges.high_temperature = true;
  h.gauges.seconds_since_last_packet = 0.25;
  h.gauges.uptime_seconds = 12.5;
  h.gauges.state = HealthState::kDegraded;
  h.gauges.reason = "3 kernel drops";
  h.gauges.storage.free_known = true;
  h.gauges.storage.free_bytes = 512'000'000'000;
  h.gauges.storage.written_bytes_per_second = {9.8e6, 1.4e6, 0, 1900};
  h.gauges.storage.written_bytes_per_second_total = 11.2019e6;
  h.gauges.storage.hours_left = 12.7;
  h.sensor_identity = SensorIdentity{"PA40\"P\\1", "4.03", "sensor"};
  SensorStatusGauges& st = h.gauges.sensor_status;
  st.polled = st.available = true;
  st.age_seconds = 1.25;
  st.interval_seconds = 5;
  st.clock_source_known = st.clock_source_ptp = true;
  st.uptime_seconds = 86400;
  st.motor_rpm = 602;
  for (std::size_t i = 0; i < st.temperatures_celsius.size(); ++i)
    st.temperatures_celsius[i] = 40.5 + static_cast<double>(i);
  st.gps_pps_locked = true;
  st.ptp_state = 1;  // tracking
  return h;
}

}  // namespace

TEST_CASE("health states have stable names", "[health]") {
  CHECK(to_string(HealthState::kOk) == "ok");
  CHECK(to_string(HealthState::kNoData) == "no_data");
  CHECK(to_string(HealthState::kDegraded) == "degraded");
  CHECK(to_string(HealthState::kError) == "error");
}

TEST_CASE("Prometheus label values are escaped", "[health]") {
  CHECK(escape_label_value("plain") == "plain");
  CHECK(escape_label_value("a\"b\\c\nd") == "a\\\"b\\\\c\\nd");
}

TEST_CASE("Prometheus text follows the textfile-collector conventions", "[health]") {
  const HealthSnapshot h = distinct_snapshot();
  const std::string text = to_prometheus(h);
  REQUIRE(text.back() == '\n');
  const std::string sensor = R"(sensor="front \"left\"\\lidar")";
  const auto s = test::prom_samples(text);

  CHECK(s.at("pandarcap_build_info{" + sensor + ",version=\"1.2.3\",decoder=\"avx2\"}") == "1");
  CHECK(s.at("pandarcap_datagrams_received_total{" + sensor + "}") ==
        std::to_string(h.counters.datagrams_received));
  CHECK(s.at("pandarcap_received_bytes_total{" + sensor + "}") ==
        std::to_string(h.counters.bytes_received));
  CHECK(s.at("pandarcap_kernel_drops_total{" + sensor + "}") ==
        std::to_string(h.counters.kernel_drops));
  CHECK(s.at("pandarcap_pcap_packets_not_recorded_total{" + sensor + "}") ==
        std::to_string(h.counters.pcap_packets_not_recorded));
  CHECK(s.at("pandarcap_not_written_bytes_total{" + sensor + "}") ==
        std::to_string(h.counters.bytes_not_written));
  CHECK(s.at("pandarcap_packets_rejected_total{" + sensor + ",reason=\"bad_marker\"}") ==
        std::to_string(h.counters.rejects[static_cast<std::size_t>(RejectReason::kBadMarker)]));
  CHECK(s.count("pandarcap_packets_rejected_total{" + sensor + ",reason=\"none\"}") == 0);
  // Microseconds in the JSON, seconds (the base unit) in Prometheus.
  CHECK(s.at("pandarcap_file_create_cpu_seconds_total{" + sensor + "}") == "1.234567");
  CHECK(s.at("pandarcap_files_created_total{" + sensor + "}") ==
        std::to_string(h.counters.files_created));
  CHECK(s.at("pandarcap_points_filtered_total{" + sensor + ",reason=\"above_max_range\"}") == "22");
  CHECK(s.at("pandarcap_motor_speed_measured_rpm{" + sensor + "}") == "599.5");
  CHECK(s.at("pandarcap_high_temperature{" + sensor + "}") == "1");
  CHECK(s.at("pandarcap_return_mode{" + sensor + ",mode=\"dual\"}") == "1");
  CHECK(s.at("pandarcap_return_mode{" + sensor + ",mode=\"last\"}") == "0");
  CHECK(s.at("pandarcap_state{" + sensor + ",state=\"degraded\"}") == "1");
  CHECK(s.at("pandarcap_state{" + sensor + ",state=\"ok\"}") == "0");

  // Every sample: a pandarcap_ name with the sensor label, a number, no timestamp; every
  // counter family ends in _total; each family has HELP and TYPE once. Label values the sensor
  // supplies (its serial, its firmware) are escaped like the sensor name.
  const std::regex sample(
      R"(^pandarcap_[a-z_]+\{sensor="(?:[^"\\]|\\.)*"(,[a-z_]+="(?:[^"\\\n]|\\.)*")*\} -?[0-9.]+(e[+-][0-9]+)?$)");
  std::istringstream in(text);
  std::string line;
  std::map<std::string, int> types;
  while (std::getline(in, line)) {
    if (line.rfind("# TYPE ", 0) == 0) {
      std::istringstream fields(line.substr(7));
      std::string name, type;
      fields >> name >> type;
      CHECK(++types[name] == 1);
      if (type == "counter") CHECK(name.ends_with("_total"));
      if (type == "gauge") CHECK_FALSE(name.ends_with("_total"));
    } else if (line[0] != '#') {
      INFO(line);
      CHECK(std::regex_match(line, sample));
    }
  }
  CHECK(types.size() > 35);
}

TEST_CASE("Latency is a Prometheus histogram and percentiles in the JSON line", "[health]") {
  const HealthSnapshot h = distinct_snapshot();
  const auto s = test::prom_samples(to_prometheus(h));
  const std::string sensor = R"(sensor="front \"left\"\\lidar")";
  const std::string name = "pandarcap_receive_to_decoded_latency_seconds";
  // Cumulative buckets: nothing below 65.5 µs, all 100 regular values below 262 µs, the outlier
  // only in the 4.19 ms bucket and above.
  CHECK(s.at(name + "_bucket{" + sensor + ",le=\"6.5536e-05\"}") == "0");
  CHECK(s.at(name + "_bucket{" + sensor + ",le=\"0.000262144\"}") == "100");
  CHECK(s.at(name + "_bucket{" + sensor + ",le=\"0.002097152\"}") == "100");
  CHECK(s.at(name + "_bucket{" + sensor + ",le=\"0.004194304\"}") == "101");
  CHECK(s.at(name + "_bucket{" + sensor + ",le=\"+Inf\"}") == "101");
  CHECK(s.at(name + "_count{" + sensor + "}") == "101");
  CHECK(std::stod(s.at(name + "_sum{" + sensor + "}")) == Approx((14'950'000 + 3'000'000) / 1e9));

  const auto j = nlohmann::json::parse(to_json_line(h));
  const auto& latency = j.at("latency");
  CHECK(latency.at("count") == 101);
  CHECK(latency.at("max_us").get<double>() == 3000.0);
  // p50 = the 51st value (150 µs), reported as its bucket's edge: within 12.5 % above.
  CHECK(latency.at("p50_us").get<double>() >= 150.0);
  CHECK(latency.at("p50_us").get<double>() <= 150.0 * 1.125);
  CHECK(latency.at("p99_us").get<double>() >= 199.0);
  CHECK(latency.at("p99_us").get<double>() <= 199.0 * 1.125);
  CHECK(latency.at("p999_us").get<double>() == 3000.0);  // the outlier, capped at the max
}

TEST_CASE("Hot-path allocations: per thread when counted, absent when not", "[health]") {
  HealthSnapshot h = distinct_snapshot();
  const std::string sensor = R"(sensor="front \"left\"\\lidar")";
  auto s = test::prom_samples(to_prometheus(h));
  CHECK(s.at("pandarcap_hot_path_allocations_total{" + sensor + ",thread=\"decode\"}") == "0");
  CHECK(s.at("pandarcap_hot_path_allocations_total{" + sensor + ",thread=\"writer\"}") == "7");
  auto j = nlohmann::json::parse(to_json_line(h));
  CHECK(j.at("counters").at("hot_path_allocations") == 7);
  CHECK(j.at("counters").at("hot_path_allocations_by_thread").at("writer") == 7);
  h.hot_path_allocations.reset();  // a sanitizer build: nothing claimed
  s = test::prom_samples(to_prometheus(h));
  CHECK(s.count("pandarcap_hot_path_allocations_total{" + sensor + ",thread=\"writer\"}") == 0);
  j = nlohmann::json::parse(to_json_line(h));
  CHECK_FALSE(j.at("counters").contains("hot_path_allocations"));
}

TEST_CASE("promtool accepts the Prometheus file, every family in it, without a note", "[health]") {
  if (test::run_command("command -v promtool >/dev/null").exit_code != 0) {
    if (std::getenv("CI") != nullptr) FAIL("promtool (package prometheus) is not installed");
    WARN("promtool not installed: skipped");
    return;
  }
  // Every family the file can hold, the optional ones included: each one in base units, with
  // nothing for promtool's linter to note (it prints nothing at all).
  HealthSnapshot h = distinct_snapshot();
  h.gauges.sensor_clock_offset_known = true;
  h.gauges.sensor_clock_offset_seconds = -0.0004;
  h.gauges.sensor_status.ptp_offset_known = true;
  h.gauges.sensor_status.ptp_offset_seconds = 2e-6;
  h.live = LiveViewHealth{1, 20, 3};
  h.frame_latency.record(40'000'000);
  test::ScratchDir dir("prom");
  const auto path = dir / "pandarcap.prom";
  const std::string text = to_prometheus(h);
  for (const char* family :
       {"pandarcap_sensor_clock_offset_seconds", "pandarcap_sensor_ptp_offset_seconds",
        "pandarcap_live_clients", "pandarcap_storage_time_left_seconds",
        "pandarcap_sensor_ptp_state", "pandarcap_hot_path_allocations_total"}) {
    INFO(family);
    CHECK(text.find(std::string("# TYPE ") + family + " ") != std::string::npos);
  }
  std::ofstream(path) << text;
  std::string said;
  const bool accepted = test::promtool_accepts(path, said);
  INFO(said);
  CHECK(accepted);
}

TEST_CASE("JSON line carries every counter, gauge, state and reason", "[health]") {
  HealthSnapshot h = distinct_snapshot();
  const std::string line = to_json_line(h);
  REQUIRE(line.back() == '\n');
  CHECK(line.find('\n') == line.size() - 1);  // one line
  const auto j = nlohmann::json::parse(line);
  CHECK(j.at("time") == "2023-11-14T22:13:20.123Z");
  CHECK(j.at("unix_time_ns") == h.unix_time_ns);
  CHECK(j.at("sensor") == h.sensor);
  CHECK(j.at("version") == "1.2.3");
  CHECK(j.at("decoder") == "avx2");
  CHECK(j.at("state") == "degraded");
  CHECK(j.at("reason") == "3 kernel drops");
  const auto& c = j.at("counters");
  CHECK(c.at("datagrams_received") == h.counters.datagrams_received);
  CHECK(c.at("bytes_received") == h.counters.bytes_received);
  CHECK(c.at("packets_accepted") == h.counters.packets_accepted);
  CHECK(c.at("packets_rejected") == h.counters.packets_rejected);
  CHECK(c.at("foreign_datagrams") == h.counters.foreign_datagrams);
  CHECK(c.at("ring_overruns") == h.counters.ring_overruns);
  CHECK(c.at("kernel_drops") == h.counters.kernel_drops);
  CHECK(c.at("frames_complete") == h.counters.frames_complete);
  CHECK(c.at("frames_partial") == h.counters.frames_partial);
  CHECK(c.at("frames_dropped_no_arena") == h.counters.frames_dropped_no_arena);
  CHECK(c.at("frames_written") == h.counters.frames_written);
  CHECK(c.at("pcap_packets_written") == h.counters.pcap_packets_written);
  CHECK(c.at("pcap_packets_not_recorded") == h.counters.pcap_packets_not_recorded);
  CHECK(c.at("bytes_not_written") == h.counters.bytes_not_written);
  CHECK(c.at("rejects").at("bad_return_mode") == 14);
  CHECK(c.at("rejects").size() == kRejectReasonCount - 1);
  CHECK(c.at("filtered_points").at("dual_too_close") == 24);
  CHECK(c.at("frames_fragment") == h.counters.frames_fragment);
  CHECK(c.at("output_name_collisions") == h.counters.output_name_collisions);
  CHECK(c.at("receive_wakeups") == h.counters.receive_wakeups);
  CHECK(c.at("writer_wakeups") == h.counters.writer_wakeups);
  CHECK(c.at("files_created") == h.counters.files_created);
  CHECK(c.at("file_create_cpu_us") == 1'234'567);
  // The scalar counters + packets_rejected + file_create_cpu_us + the two reason maps + the
  // hot-path allocation total and its per-thread map.
  CHECK(c.size() == kHealthCounterCount + 6);
  const auto& g = j.at("gauges");
  CHECK(g.at("rpm_tail") == 600.0);
  CHECK(g.at("rpm_measured") == 599.5);
  CHECK(g.at("return_mode") == "dual");
  CHECK(g.at("high_temperature") == true);
  CHECK(g.at("seconds_since_last_packet") == 0.25);
  // The last impossible tail time: null before one, its field and value after.
  CHECK(g.at("last_invalid_time").is_null());
  h.gauges.last_invalid_time = "month 31";
  CHECK(nlohmann::json::parse(to_json_line(h)).at("gauges").at("last_invalid_time") == "month 31");
}

TEST_CASE("JSON line survives a reason that is not UTF-8", "[health]") {
  HealthSnapshot h;
  h.gauges.reason = "write failed: \xff\xfe";
  const auto j = nlohmann::json::parse(to_json_line(h));
  CHECK(j.at("state") == "no_data");
  CHECK(j.at("reason").get<std::string>().rfind("write failed: ", 0) == 0);
}

TEST_CASE("Sensor identity and status over PTC: fresh values reported, stale ones not",
          "[health][ptc]") {
  HealthSnapshot h = distinct_snapshot();
  auto prom = test::prom_samples(to_prometheus(h));
  const std::string sensor = "sensor=\"front \\\"left\\\"\\\\lidar\"";
  CHECK(prom.at("pandarcap_sensor_info{" + sensor +
                ",serial=\"PA40\\\"P\\\\1\",firmware=\"4.03\",calibration_source=\"sensor\"}") ==
        "1");
  CHECK(prom.at("pandarcap_sensor_status_age_seconds{" + sensor + "}") == "1.25");
  CHECK(prom.at("pandarcap_sensor_status_stale{" + sensor + "}") == "0");
  CHECK(prom.at("pandarcap_sensor_uptime_seconds{" + sensor + "}") == "86400");
  CHECK(prom.at("pandarcap_sensor_motor_speed_rpm{" + sensor + "}") == "602");
  CHECK(prom.at("pandarcap_sensor_temperature_celsius{" + sensor + ",board=\"bottom_t1\"}") ==
        "40.5");
  CHECK(prom.at("pandarcap_sensor_temperature_celsius{" + sensor + ",board=\"top_rt5\"}") ==
        "47.5");
  CHECK(prom.at("pandarcap_sensor_ptp_state{" + sensor + ",state=\"tracking\"}") == "1");
  CHECK(prom.at("pandarcap_sensor_ptp_state{" + sensor + ",state=\"locked\"}") == "0");
  CHECK(prom.at("pandarcap_sensor_clock_source{" + sensor + ",source=\"ptp\"}") == "1");
  CHECK(prom.at("pandarcap_sensor_gps_pps_locked{" + sensor + "}") == "1");
  auto json = nlohmann::json::parse(to_json_line(h));
  CHECK(json["sensor_info"]["serial"] == "PA40\"P\\1");
  CHECK(json["sensor_info"]["calibration_source"] == "sensor");
  CHECK(json["sensor_status"]["ptp_state"] == "tracking");
  CHECK(json["sensor_status"]["clock_source"] == "ptp");
  CHECK(json["sensor_status"]["temperatures_celsius"]["laser_rt_l"] == Approx(42.5));
  CHECK(json["counters"]["ptc_errors"].is_number());

  // Stale: age and the flag, and none of the values, as if they were current.
  h.gauges.sensor_status.stale = true;
  h.gauges.sensor_status.age_seconds = 16;
  prom = test::prom_samples(to_prometheus(h));
  CHECK(prom.at("pandarcap_sensor_status_stale{" + sensor + "}") == "1");
  CHECK(prom.count("pandarcap_sensor_uptime_seconds{" + sensor + "}") == 0);
  CHECK(prom.count("pandarcap_sensor_ptp_state{" + sensor + ",state=\"tracking\"}") == 0);
  json = nlohmann::json::parse(to_json_line(h));
  CHECK(json["sensor_status"]["stale"] == true);
  CHECK_FALSE(json["sensor_status"].contains("ptp_state"));

  // Not polled: the identity only.
  h.gauges.sensor_status = SensorStatusGauges{};
  prom = test::prom_samples(to_prometheus(h));
  CHECK(prom.count("pandarcap_sensor_status_stale{" + sensor + "}") == 0);
  json = nlohmann::json::parse(to_json_line(h));
  CHECK(json["sensor_status"]["polled"] == false);
}

TEST_CASE("The sensor clock offset is a gauge and a JSON key once known, absent before",
          "[health]") {
  HealthSnapshot h;
  h.sensor = "front";
  CHECK(to_prometheus(h).find("sensor_clock_offset_seconds") == std::string::npos);
  CHECK_FALSE(
      nlohmann::json::parse(to_json_line(h)).at("gauges").contains("sensor_clock_offset_seconds"));
  h.gauges.sensor_clock_offset_known = true;
  h.gauges.sensor_clock_offset_seconds = -168035162.5;
  CHECK(to_prometheus(h).find("pandarcap_sensor_clock_offset_seconds{sensor=\"front\"} "
                              "-168035162.5\n") != std::string::npos);
  CHECK(nlohmann::json::parse(to_json_line(h)).at("gauges").at("sensor_clock_offset_seconds") ==
        -168035162.5);
}

TEST_CASE("UTC text: RFC 3339 to the digits asked, floored before 1970", "[health]") {
  std::string out;
  append_rfc3339(out, 1'795'348'800'123'456'789, 3);
  CHECK(out == "2026-11-22T12:00:00.123Z");
  out.clear();
  append_rfc3339(out, 1'795'348'800'123'456'789, 9);
  CHECK(out == "2026-11-22T12:00:00.123456789Z");
  out.clear();
  append_rfc3339(out, -1, 3);  // 1 ns before the epoch
  CHECK(out == "1969-12-31T23:59:59.999Z");
  CHECK(split_unix_ns(-1).seconds == -1);
  CHECK(split_unix_ns(-1).nanoseconds == 999'999'999);
}
