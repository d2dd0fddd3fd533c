// The faults of a vehicle day, where users meet them: a full disk with health on it (the default
// layout), folders that vanish, a sensor whose status is garbage, inputs that are not files, a
// stop during the start, control characters in paths, the bench generator's own clock, and all of
// them at once against one daemon. Health must stay fresh (never more than 2 s old) and true.
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <catch2/catch.hpp>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <regex>
#include <string>
#include <system_error>
#include <thread>
#include <vector>

#include "bench/child_process.hpp"
#include "support/hostile_ptc_server.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
using namespace std::chrono_literals;
using nlohmann::json;
namespace fs = std::filesystem;
using test::health_counter;

namespace {

// Removes a folder the daemon is writing into, as `rm -rf` does: the daemon may put a file in
// while it is being emptied ("Directory not empty"), so it is emptied again until the removal
// goes through. (The daemon may make it again at once: that is what is under test.)
void remove_folder(const fs::path& dir) {
  std::error_code error;
  for (int attempt = 0; attempt < 100; ++attempt) {
    fs::remove_all(dir, error);
    if (!error) return;
  }
  FAIL("cannot remove " << dir << ": " << error.message());
}

double now_s() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

// Both health files as they are now. Fresh: each rewritten within the last 2 s (the .prom by
// its modification time, health.jsonl by its last record's time).
struct HealthSample {
  bool prom_fresh = false;
  bool jsonl_fresh = false;
  json last;
  std::string prom;
};
HealthSample sample(const fs::path& health_dir) {
  HealthSample s;
  const fs::path prom = health_dir / "pandarcap.prom";
  struct stat info {};
  if (::stat(prom.c_str(), &info) == 0) {
    const double mtime =
        static_cast<double>(info.st_mtim.tv_sec) + static_cast<double>(info.st_mtim.tv_nsec) / 1e9;
    s.prom_fresh = now_s() - mtime <= 2.0;
    s.prom = harness::read_file(prom);
  }
  const auto lines = test::json_lines(health_dir / "health.jsonl");
  if (!lines.empty()) {
    s.last = lines.back();
    s.jsonl_fresh = now_s() - s.last.at("unix_time_ns").get<double>() / 1e9 <= 2.0;
  }
  return s;
}

// Waits for the next health record after `after` (its uptime), then samples.
HealthSample next_sample(const fs::path& health_dir, double after_uptime) {
  HealthSample s;
  harness::wait_until(
      [&] {
        s = sample(health_dir);
        return !s.last.is_null() &&
               s.last.at("gauges").at("uptime_seconds").get<double>() > after_uptime;
      },
      3s);
  return s;
}

double uptime(const json& record) {
  return record.is_null() ? -1.0 : record.at("gauges").at("uptime_seconds").get<double>();
}

// Every datagram is accounted for (core/health/health.hpp). While packets flow the decoder's counts
// are its last snapshot (once a second) and may lag the receive thread's: at most as many; at
// rest (the final record) exactly.
void check_identity(const json& h, bool at_rest = true) {
  INFO(h.dump());
  const std::uint64_t received = health_counter(h, "datagrams_received");
  const std::uint64_t accounted =
      health_counter(h, "packets_accepted") + health_counter(h, "packets_rejected") +
      health_counter(h, "duplicate_packets") + health_counter(h, "foreign_datagrams") +
      health_counter(h, "ring_overruns");
  if (at_rest) {
    CHECK(received == accounted);
  } else {
    CHECK(received >= accounted);
  }
}

// Packets in the recordings on disk.
std::uint64_t packets_on_disk(const fs::path& raw) {
  std::uint64_t packets = 0;
  for (const fs::path& pcap : test::files_ending(raw, ".pcap"))
    packets += test::read_capture(pcap).second;
  return packets;
}

// "N packets recorded" from the exit summary.
std::uint64_t summary_recorded(const std::string& log) {
  std::smatch m;
  const std::regex recorded(R"(([0-9]+) packets recorded)");
  REQUIRE(std::regex_search(log, m, recorded));
  return std::stoull(m[1].str());
}

// Fills the file system holding `dir` to its last block (another process would): a file of
// zeros, written until the disk says no.
fs::path fill_up(const fs::path& dir) {
  const fs::path filler = dir / "someone-elses-file";
  std::FILE* f = std::fopen(filler.c_str(), "wb");
  REQUIRE(f != nullptr);
  static const std::vector<char> zeros(1 << 20);
  while (std::fwrite(zeros.data(), 1, zeros.size(), f) == zeros.size()) {
  }
  while (std::fwrite(zeros.data(), 1, 4096, f) == 4096) {
  }
  std::fclose(f);
  return filler;
}

}  // namespace

TEST_CASE("health never freezes: the default layout on a small disk, full and freed",
          "[daemon][reliability][disk][road][threads]") {
  test::ScratchDir dir("road-full-disk");
  const fs::path mount_point = dir / "out";
  fs::create_directories(mount_point);
  const fs::path config = dir / "full.toml";
  std::ofstream(config) << "[output]\npcap_rotate_bytes = 1048576\n";
  const auto args = test::tmpfs_run_args(
      mount_point, "64m", test::binary("pandarcapd"),
      {"--allow-root", "-c", config.string(), "--simulate", "--output-dir", mount_point.string()},
      true);
  if (args.empty()) {
    WARN("cannot create a mount namespace here (no root, no user namespaces): not tested");
    return;
  }
  harness::ChildProcess daemon("/usr/bin/unshare", args, dir / "log.txt");
  INFO(daemon.log());
  REQUIRE(harness::wait_until([&] { return daemon.logged("ready:"); }, 20s));
  const int pid = test::tmpfs_program_pid(mount_point);
  REQUIRE(pid > 0);
  const fs::path view = test::tmpfs_view(pid, mount_point);
  const fs::path health = view / "health";
  REQUIRE(harness::wait_until([&] { return !sample(health).last.is_null(); }, 10s));

  // Frames and recordings fill the 64 MB to the 32 MB the health files keep (a second or two);
  // then, every second, both files are rewritten and say so.
  REQUIRE(harness::wait_until(
      [&] { return health_counter(sample(health).last, "write_errors") > 0; }, 20s));
  double last_uptime = uptime(sample(health).last);
  for (int second = 0; second < 4; ++second) {
    const HealthSample s = next_sample(health, last_uptime);
    INFO(s.last.dump());
    CHECK(s.prom_fresh);
    CHECK(s.jsonl_fresh);
    CHECK(s.last.at("state") == "degraded");
    CHECK(s.last.at("reason").get<std::string>().find("no space: ") != std::string::npos);
    CHECK(s.prom.find("state=\"degraded\"} 1") != std::string::npos);
    last_uptime = uptime(s.last);
  }

  // Space comes back (the frames are moved off): writing resumes within 2 s (and fills the room
  // again: a sensor writes 20 MB/s), health goes on every second, counting what it writes.
  const std::uint64_t frames_before = health_counter(sample(health).last, "frames_written");
  for (const fs::path& pcd : test::files_ending(view / "frames", ".pcd"))
    fs::remove(pcd);
  CHECK(harness::wait_until([&] { return !test::files_ending(view / "frames", ".pcd").empty(); },
                            2s));
  for (int second = 0; second < 3; ++second) {
    const HealthSample s = next_sample(health, last_uptime);
    INFO(s.last.dump());
    CHECK(s.prom_fresh);
    CHECK(s.jsonl_fresh);
    last_uptime = uptime(s.last);
  }
  CHECK(health_counter(sample(health).last, "frames_written") > frames_before);

  // Someone else fills the disk to its last block: the health files take pieces of their
  // reserve, and go on every second.
  const fs::path filler = fill_up(view);
  for (int second = 0; second < 4; ++second) {
    const HealthSample s = next_sample(health, last_uptime);
    INFO(s.last.dump());
    CHECK(s.prom_fresh);
    CHECK(s.jsonl_fresh);
    CHECK(s.last.at("state") == "degraded");
    last_uptime = uptime(s.last);
  }
  CHECK(daemon.logged("of the health reserve given back"));

  // The final record is written at exit, full disk and all (the health folder is copied out of
  // the namespace when the daemon ends).
  REQUIRE(::kill(pid, SIGTERM) == 0);
  REQUIRE(daemon.wait_exit(20s) == 0);
  CHECK(daemon.logged("final health: state degraded"));
  const auto records =
      test::json_lines(fs::path(mount_point.string() + ".after") / "health" / "health.jsonl");
  REQUIRE_FALSE(records.empty());
  CHECK(uptime(records.back()) > last_uptime);
  CHECK(records.back().at("state") == "degraded");
  check_identity(records.back());
}

TEST_CASE("folders removed while running come back, and recorded is what is on disk",
          "[daemon][reliability][road][threads]") {
  test::ScratchDir dir("road-vanish");
  const fs::path out = dir / "out";
  const fs::path config = dir / "vanish.toml";
  std::ofstream(config) << "[output]\npcap_rotate_seconds = 1\n";
  harness::ChildProcess daemon(
      test::binary("pandarcapd"),
      {"--allow-root", "-c", config.string(), "--simulate", "--output-dir", out.string()},
      dir / "log.txt");
  INFO(daemon.log());
  REQUIRE(harness::wait_until([&] { return daemon.logged("ready:"); }, 20s));
  REQUIRE(harness::wait_until([&] { return test::files_ending(out / "raw", ".pcap").size() >= 2; },
                              10s));
  // A clean-up script, or a USB disk pulled: recordings (finished and open), frames and health go.
  for (const char* folder : {"raw", "frames", "health"})
    remove_folder(out / folder);
  const double removed_at = now_s();
  // Each comes back at its next write, the health within a second or two.
  CHECK(harness::wait_until([&] { return sample(out / "health").jsonl_fresh; }, 4s));
  CHECK(harness::wait_until([&] { return sample(out / "health").prom_fresh; }, 4s));
  CHECK(
      harness::wait_until([&] { return !test::files_ending(out / "frames", ".pcd").empty(); }, 4s));
  CHECK(harness::wait_until([&] { return !test::files_ending(out / "raw", ".pcap").empty(); }, 4s));
  CHECK(now_s() - removed_at < 5);
  // The loss is counted, and said (degraded) in the second it was seen.
  REQUIRE(harness::wait_until(
      [&] { return health_counter(sample(out / "health").last, "pcap_packets_lost") > 0; }, 4s));
  bool said = false;
  for (const json& record : test::json_lines(out / "health" / "health.jsonl")) {
    said = said || record.at("reason").get<std::string>().find(
                       "recorded packets lost (recording "
                       "removed)") != std::string::npos;
  }
  CHECK(said);
  CHECK(daemon.logged("was removed while running: made again"));

  daemon.signal(SIGTERM);
  REQUIRE(daemon.wait_exit(20s) == 0);
  const json h = test::last_health_record(out);
  INFO(h.dump());
  check_identity(h);
  // The summary's "packets recorded" is what the recordings on disk hold, and every datagram is
  // either there or counted as not recorded (or, under ThreadSanitizer, overrun by the ring).
  const std::uint64_t on_disk = packets_on_disk(out / "raw");
  CHECK(summary_recorded(daemon.log()) == on_disk);
  const std::uint64_t kept =
      health_counter(h, "pcap_packets_written") - health_counter(h, "pcap_packets_lost");
  CHECK(kept == on_disk);
  const std::uint64_t overruns = test::check_ring_overruns(h);
  const std::uint64_t accounted = on_disk + health_counter(h, "packets_not_recorded") + overruns;
  CHECK(health_counter(h, "datagrams_received") == accounted);
  CHECK(health_counter(h, "packets_not_recorded") >= health_counter(h, "pcap_packets_lost"));
}

TEST_CASE("a FIFO, socket or device as an input is refused at once", "[daemon][road][threads]") {
  test::ScratchDir dir("road-fifo");
  const fs::path fifo = dir / "input";
  REQUIRE(::mkfifo(fifo.c_str(), 0600) == 0);
  const std::string daemon = test::pandarcapd_command() + " --output-dir " + (dir / "out").string();
  const auto start = std::chrono::steady_clock::now();
  const auto replay = test::run_command(daemon + " --replay " + fifo.string() + " 2>&1");
  CHECK(replay.exit_code == 66);
  CHECK(replay.out.find("not a regular file") != std::string::npos);
  const auto config = test::run_command(daemon + " -c " + fifo.string() + " 2>&1");
  CHECK(config.exit_code == 78);
  CHECK(config.out.find("not a regular file") != std::string::npos);
  const auto calibration = test::run_command(daemon + " --calibration " + fifo.string() +
                                             " --calibration-source file --simulate 2>&1");
  CHECK(calibration.exit_code == 78);
  CHECK(calibration.out.find("not a regular file") != std::string::npos);
  const auto device = test::run_command(daemon + " --replay /dev/zero 2>&1");
  CHECK(device.exit_code == 66);
  // None waited for a writer.
  CHECK(std::chrono::steady_clock::now() - start < 10s);
}

TEST_CASE("SIGTERM during the start ends it within a second", "[daemon][road][threads]") {
  test::ScratchDir dir("road-start-stop");
  // A sensor that takes the connection and never answers, with the longest deadline allowed: the
  // start would wait a minute per question.
  test::HostilePtcServer silent(test::Hostile::kSilent);
  const fs::path config = dir / "slow.toml";
  std::ofstream(config) << "[sensor]\nptc_timeout_ms = 60000\ncalibration_source = \"sensor\"\n";
  harness::ChildProcess daemon(
      test::binary("pandarcapd"),
      {"--allow-root", "-c", config.string(), "--simulate", "--ptc-port",
       std::to_string(silent.port()), "--output-dir", (dir / "out").string()},
      dir / "log.txt");
  INFO(daemon.log());
  REQUIRE(harness::wait_until([&] { return silent.connections() >= 1; }, 10s));
  const auto asked = std::chrono::steady_clock::now();
  daemon.signal(SIGTERM);
  const auto status = daemon.wait_exit(5s);
  CHECK(std::chrono::steady_clock::now() - asked < 1500ms);
  CHECK(status == 0);
  CHECK(daemon.logged("stop requested while starting"));
  CHECK_FALSE(daemon.logged("ready:"));
}

TEST_CASE("control characters in a configured path are escaped in every line",
          "[daemon][road][threads]") {
  test::ScratchDir dir("road-log");
  const std::string forged = "2026-01-01T00:00:00.000 [info] all is well";
  const fs::path out = dir / ("out\n" + forged);
  const auto r = test::run_command(test::pandarcapd_command() + " --simulate --duration 1 " +
                                   "--output-dir '" + out.string() + "' 2>&1");
  INFO(r.out);
  REQUIRE(r.exit_code == 0);
  std::istringstream lines(r.out);
  std::size_t escaped = 0;
  for (std::string line; std::getline(lines, line);) {
    CHECK(line.rfind(forged, 0) == std::string::npos);  // no line of its own
    if (line.find("out\\x0a" + forged) != std::string::npos) ++escaped;
  }
  CHECK(escaped >= 2);  // the log's "ready: writing to" and the summary's "outputs in"
  // --check-config's lines too.
  const auto check = test::run_command(test::pandarcapd_command() + " --check-config " +
                                       "--output-dir '" + out.string() + "' 2>&1");
  CHECK(check.out.find('\n' + forged) == std::string::npos);
}

TEST_CASE("check-config checks the free space the start needs, and prints it",
          "[daemon][road][disk][threads]") {
  test::ScratchDir dir("road-check-space");
  const auto fine = test::run_command(test::pandarcapd_command() + " --check-config --output-dir " +
                                      (dir / "out").string() + " 2>&1");
  CHECK(fine.exit_code == 0);
  CHECK(fine.out.find("MiB free, 40 MiB needed") != std::string::npos);
  const fs::path mount_point = dir / "small";
  fs::create_directories(mount_point);
  const auto args = test::tmpfs_run_args(
      mount_point, "16m", test::binary("pandarcapd"),
      {"--allow-root", "--check-config", "--output-dir", mount_point.string()});
  if (args.empty()) {
    WARN("cannot create a mount namespace here: the full-disk half not tested");
    return;
  }
  harness::ChildProcess check("/usr/bin/unshare", args, dir / "check.txt");
  CHECK(check.wait_exit(20s) == 73);
  CHECK(check.logged("40 MiB needed"));
  CHECK(check.logged("kept for the health files"));
  // And the start says the same.
  std::vector<std::string> start_args = test::tmpfs_run_args(
      mount_point, "16m", test::binary("pandarcapd"),
      {"--allow-root", "--simulate", "--duration", "1", "--output-dir", mount_point.string()});
  harness::ChildProcess start("/usr/bin/unshare", start_args, dir / "start.txt");
  CHECK(start.wait_exit(20s) == 73);
  CHECK_FALSE(start.logged("ready:"));
}

TEST_CASE("a sensor status of impossible values is left out, counted and named",
          "[daemon][road][ptc][threads]") {
  test::ScratchDir dir("road-garbage-status");
  test::HostilePtcServer garbage(test::Hostile::kGarbageStatus);
  const fs::path out = dir / "out";
  harness::ChildProcess daemon(
      test::binary("pandarcapd"),
      {"--allow-root", "--simulate", "--ptc-port", std::to_string(garbage.port()),
       "--status-interval", "0.2", "--output-dir", out.string()},
      dir / "log.txt");
  INFO(daemon.log());
  json h;
  REQUIRE(harness::wait_until(
      [&] {
        h = test::last_health_record(out);
        return !h.is_null() && h.at("sensor_status").value("available", false) &&
               health_counter(h, "sensor_status_implausible") >= 2;
      },
      15s));
  INFO(h.dump());
  const json& st = h.at("sensor_status");
  for (const char* absent : {"motor_rpm", "uptime_seconds", "gps_pps_locked", "ptp_state"})
    CHECK_FALSE(st.contains(absent));
  CHECK_FALSE(st.at("temperatures_celsius").contains("bottom_t1"));
  CHECK_FALSE(st.at("temperatures_celsius").contains("laser_rt_r"));
  CHECK(st.at("temperatures_celsius").contains("bottom_t2"));  // the plausible ones stay
  CHECK(st.at("gps_nmea_locked").is_boolean());
  const auto implausible = st.at("implausible").get<std::vector<std::string>>();
  CHECK(implausible == std::vector<std::string>{"uptime_seconds", "motor_rpm",
                                                "temperature_bottom_t1", "temperature_laser_rt_r",
                                                "gps_pps_locked", "ptp_state"});
  CHECK(h.at("state") == "degraded");
  const std::string reason = h.at("reason").get<std::string>();
  CHECK(reason.find("sensor status implausible: uptime 117 years (0..10); motor speed 53029 RPM "
                    "(0..1300)") != std::string::npos);
  const std::string prom = harness::read_file(out / "health" / "pandarcap.prom");
  CHECK(prom.find("pandarcap_sensor_motor_speed_rpm") == std::string::npos);
  CHECK(prom.find("pandarcap_sensor_status_implausible_total") != std::string::npos);
  CHECK(daemon.logged("sensor status: implausible values left out"));
  daemon.signal(SIGTERM);
  CHECK(daemon.wait_exit(20s) == 0);
}

TEST_CASE("pandarcap-bench send's clock runs: its stream cuts into whole frames",
          "[daemon][road][bench][threads]") {
  test::ScratchDir dir("road-send-clock");
  const fs::path out = dir / "out";
  const std::uint16_t port = harness::free_udp_port();
  harness::ChildProcess daemon(test::binary("pandarcapd"),
                               {"--allow-root", "--host-ip", "127.0.0.1", "--port",
                                std::to_string(port), "--output-dir", out.string()},
                               dir / "log.txt");
  INFO(daemon.log());
  REQUIRE(harness::wait_until([&] { return daemon.logged("ready:"); }, 20s));
  const auto sent = test::run_command(test::binary("pandarcap-bench").string() +
                                      " send --json --rate 3600 --seconds 3 --rpm 600 " +
                                      "--return-mode dual --port " + std::to_string(port));
  REQUIRE(sent.exit_code == 0);
  const json report = json::parse(sent.out);
  const std::uint64_t packets = report.at("sent").get<std::uint64_t>();
  REQUIRE(harness::wait_until(
      [&] {
        return health_counter(test::last_health_record(out), "datagrams_received") >= packets;
      },
      5s));
  daemon.signal(SIGTERM);
  REQUIRE(daemon.wait_exit(20s) == 0);
  const json h = test::last_health_record(out);
  INFO(h.dump());
  // 3 s at 600 RPM: 30 revolutions, the first and the last partial where the stream began and
  // ended. The clock never restarts inside the stream, so nothing else is cut. A revolution the
  // decoder had no free arena for (a writer starved by a sanitizer's slowness) was cut too, and
  // counted as dropped.
  const std::uint64_t revolutions = packets / 360;
  const std::uint64_t cut =
      health_counter(h, "frames_complete") + health_counter(h, "frames_dropped_no_arena") + 2;
  const std::uint64_t partial = health_counter(h, "frames_partial");
  const std::uint64_t overruns = test::check_ring_overruns(h);
  if (overruns == 0) {
    CHECK(cut >= revolutions);
    CHECK(partial <= 3);  // where it began, ended, and the flush
  } else {
    // ThreadSanitizer on a busy machine: the datagrams the ring overran are the only ones lost,
    // and each run of them may cut the revolution it fell in into two partial frames (or take
    // it whole).
    const std::uint64_t gaps = health_counter(h, "sequence_gaps");
    CHECK(health_counter(h, "sequence_lost") <= overruns);
    CHECK(partial <= 3 + 2 * gaps);
    CHECK(cut + partial + overruns / 360 + gaps >= revolutions);
  }
  CHECK(health_counter(h, "backward_timestamp_packets") == 0);
  CHECK(health_counter(h, "outlier_packets") == 0);
  // Its clock is the host's: a synchronised sensor, not one off by days.
  CHECK(std::abs(h.at("gauges").at("sensor_clock_offset_seconds").get<double>()) < 1.0);
  // Frame names follow time: never the same second twice in the same revolution's place.
  std::vector<std::string> stamps;
  for (const fs::path& pcd : test::files_ending(out / "frames", ".pcd"))
    stamps.push_back(pcd.filename().string().substr(13));
  CHECK(std::is_sorted(stamps.begin(), stamps.end()));
}

namespace {

// Counters that only grow: a Prometheus counter that went down would read as a restart.
void check_monotonic(const json& before, const json& after) {
  if (before.is_null()) return;
  for (const auto& [name, value] : before.at("counters").items()) {
    if (!value.is_number_unsigned()) continue;
    INFO(name);
    CHECK(health_counter(after, name) >= value.get<std::uint64_t>());
  }
}

// A compressed vehicle day against one running daemon (live, 3600 packets/s over loopback, on a
// 64 MB disk with health on it): its own outputs fill the disk all along; a switch loop doubles
// packets and the sensor's clock glitches; the sensor's control port flaps and answers garbage;
// raw/ and frames/ are removed; SIGHUP comes twenty times in a second; another process fills the
// disk to its last block, then frees it. Every second: both health files fresh, every datagram
// accounted for, no counter going back, a failing write said. At the end: what the recordings on
// disk hold is what the summary says was recorded.
void vehicle_day(int seconds) {
  test::ScratchDir dir("road-vehicle-day");
  const fs::path mount_point = dir / "out";
  fs::create_directories(mount_point);
  test::HostilePtcServer sensor_port(test::Hostile::kFlapping);
  const std::uint16_t port = harness::free_udp_port();
  const fs::path config = dir / "vehicle.toml";
  std::ofstream(config) << "[sensor]\nsensor_ip = \"127.0.0.1\"\nhost_ip = \"127.0.0.1\"\n"
                        << "data_port = " << port << "\nptc_port = " << sensor_port.port()
                        << "\nptc_timeout_ms = 300\nstatus_interval_seconds = 0.5\n"
                        << "[output]\npcap_rotate_seconds = 2\n";
  const auto args = test::tmpfs_run_args(
      mount_point, "64m", test::binary("pandarcapd"),
      {"--allow-root", "-c", config.string(), "--output-dir", mount_point.string()}, true);
  if (args.empty()) {
    WARN("cannot create a mount namespace here (no root, no user namespaces): not tested");
    return;
  }
  harness::ChildProcess daemon("/usr/bin/unshare", args, dir / "daemon.txt");
  INFO(daemon.log());
  REQUIRE(harness::wait_until([&] { return daemon.logged("ready:"); }, 30s));
  const int pid = test::tmpfs_program_pid(mount_point);
  REQUIRE(pid > 0);
  const fs::path view = test::tmpfs_view(pid, mount_point);
  const fs::path health = view / "health";

  harness::ChildProcess traffic(
      test::binary("pandarcap-bench"),
      {"send", "--json", "--rate", "3600", "--seconds", std::to_string(seconds), "--port",
       std::to_string(port), "--rpm", "600", "--return-mode", "dual", "--duplicate-fraction",
       "0.002", "--glitch-fraction", "0.002"},
      dir / "traffic.txt");

  const auto start = std::chrono::steady_clock::now();
  const auto elapsed = [&] {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  };
  json previous;
  double last_uptime = -1;
  bool removed = false, hangups = false, filled = false, freed = false;
  fs::path filler;
  int fresh_seconds = 0;
  while (elapsed() < seconds) {
    const HealthSample s = next_sample(health, last_uptime);
    INFO("at " << elapsed() << " s: " << s.last.dump());
    CHECK(s.prom_fresh);
    CHECK(s.jsonl_fresh);
    if (s.prom_fresh && s.jsonl_fresh) ++fresh_seconds;
    check_identity(s.last, false);
    check_monotonic(previous, s.last);
    if (!previous.is_null() &&
        health_counter(s.last, "write_errors") > health_counter(previous, "write_errors")) {
      CHECK(s.last.at("state") == "degraded");  // a failing write is never "ok"
    }
    previous = s.last;
    last_uptime = uptime(s.last);
    // The day's events, each once, in order.
    if (!removed && elapsed() > seconds * 0.15) {
      remove_folder(view / "raw");
      remove_folder(view / "frames");
      removed = true;
    } else if (!hangups && elapsed() > seconds * 0.3) {
      for (int i = 0; i < 20; ++i) {
        ::kill(pid, SIGHUP);
        std::this_thread::sleep_for(50ms);  // a storm's pace, not a synchronisation
      }
      hangups = true;
    } else if (!filled && elapsed() > seconds * 0.45) {
      filler = fill_up(view);
      filled = true;
    } else if (filled && !freed && elapsed() > seconds * 0.6) {
      fs::remove(filler);
      for (const fs::path& pcd : test::files_ending(view / "frames", ".pcd"))
        fs::remove(pcd);
      freed = true;
    }
  }
  CHECK(fresh_seconds >= seconds - 2);
  REQUIRE(traffic.wait_exit(30s) == 0);
  const json sent = json::parse(traffic.log());
  const std::uint64_t datagrams =
      sent.at("sent").get<std::uint64_t>() + sent.at("duplicates_sent").get<std::uint64_t>();
  REQUIRE(harness::wait_until(
      [&] {
        const json h = sample(health).last;
        return health_counter(h, "datagrams_received") + health_counter(h, "kernel_drops") >=
               datagrams;
      },
      10s));
  REQUIRE(::kill(pid, SIGTERM) == 0);
  REQUIRE(daemon.wait_exit(30s) == 0);

  const fs::path after(mount_point.string() + ".after");
  const auto records = test::json_lines(after / "health" / "health.jsonl");
  REQUIRE_FALSE(records.empty());
  const json& h = records.back();
  INFO(h.dump());
  check_identity(h);
  CHECK(health_counter(h, "datagrams_received") == datagrams);
  CHECK(health_counter(h, "kernel_drops") == 0);
  // A datagram the ring overflowed (TSan only, see check_ring_overruns) never reached the
  // decoder: it is neither counted as a copy or an outlier nor recorded.
  const std::uint64_t overruns = test::check_ring_overruns(h);
  const auto duplicates_sent = sent.at("duplicates_sent").get<std::uint64_t>();
  const auto glitches_sent = sent.at("glitches_sent").get<std::uint64_t>();
  // Each copy counted as one, each glitch as an outlier (a copy of a glitched packet is a copy).
  CHECK(health_counter(h, "duplicate_packets") <= duplicates_sent);
  CHECK(health_counter(h, "duplicate_packets") + overruns >= duplicates_sent);
  CHECK(health_counter(h, "outlier_packets") + overruns >= glitches_sent);
  CHECK(health_counter(h, "outlier_packets") <= sent.at("glitches_sent").get<std::uint64_t>() + 2);
  // Revolutions stay whole through all of it: 10 a second, less the first and last. A revolution
  // that lost a datagram to a ring overrun (ThreadSanitizer only, above) closes partial, counted:
  // each such frame lost at least one datagram, so there are no more of them than overruns.
  const double revolutions = seconds * 10.0;
  const std::uint64_t partial_by_overruns = std::min(health_counter(h, "frames_partial"), overruns);
  CHECK(static_cast<double>(health_counter(h, "frames_complete") + partial_by_overruns) >=
        0.95 * revolutions - 2);
  // The sensor's garbage was seen, left out, and its flapping counted.
  CHECK(health_counter(h, "sensor_status_implausible") >= 1);
  CHECK(health_counter(h, "ptc_errors") >= 1);
  // Recorded is what is on disk.
  const std::uint64_t on_disk = packets_on_disk(after / "raw");
  CHECK(summary_recorded(daemon.log()) == on_disk);
  const std::uint64_t accounted = on_disk + health_counter(h, "packets_not_recorded") + overruns;
  CHECK(health_counter(h, "datagrams_received") == accounted);
  CHECK(daemon.logged("was removed while running: made again"));
}

}  // namespace

TEST_CASE("a compressed vehicle day: every fault against one daemon, health fresh and true",
          "[daemon][road][vehicle-day][threads]") {
  vehicle_day(40);
}

// The long day: PANDARCAP_VEHICLE_DAY_SECONDS=600 build/release/bin/pandarcap_tests
// "[.vehicle-day]"
TEST_CASE("a long vehicle day (PANDARCAP_VEHICLE_DAY_SECONDS, default 600)",
          "[.vehicle-day][daemon][road][threads]") {
  const char* seconds = std::getenv("PANDARCAP_VEHICLE_DAY_SECONDS");
  vehicle_day(seconds != nullptr ? std::atoi(seconds) : 600);
}
