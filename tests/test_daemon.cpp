// pandarcapd end to end: the real binary on real loopback sockets and real files. Replay of the
// real capture, live UDP from 127.0.0.1 with a foreign sender on 127.0.0.2, SIGTERM drain, SIGHUP
// rotation, the simulated sensor, configuration errors, and sd_notify over a fake NOTIFY_SOCKET.
// Every wait is a condition with a deadline (wait_until / wait_exit), never a bare sleep.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "bench/child_process.hpp"
#include "core/decode/decoder_target.hpp"
#include "core/sim/synthetic_sensor.hpp"
#include "daemon/pcap/capture_reader.hpp"
#include "daemon/pcap/pcap_writer.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
using namespace std::chrono_literals;
using nlohmann::json;
namespace fs = std::filesystem;
using test::files_ending;
using test::health_counter;
using test::health_records;

namespace {

const char* kDualCapture = "pandar40p_nebula_dual_600rpm_1262B.pcap";
const char* kCalibration = "nebula_Pandar40P_calibration.csv";

std::vector<std::vector<std::uint8_t>> payloads_of(const fs::path& capture) {
  CaptureReader reader(capture.string());
  CaptureRecord record;
  std::vector<std::vector<std::uint8_t>> payloads;
  while (reader.next(record) == CaptureStatus::kRecord) {
    payloads.emplace_back(record.payload.begin(), record.payload.end());
  }
  return payloads;
}

// Every record of every pcap in `dir`, in file-name order.
std::vector<std::vector<std::uint8_t>> recorded(const fs::path& dir) {
  std::vector<fs::path> files;
  for (const auto& entry : fs::directory_iterator(dir)) {
    if (entry.path().extension() == ".pcap") files.push_back(entry.path());
  }
  std::sort(files.begin(), files.end());
  std::vector<std::vector<std::uint8_t>> all;
  for (const fs::path& file : files) {
    const auto part = payloads_of(file);
    all.insert(all.end(), part.begin(), part.end());
  }
  return all;
}

json last_health(const fs::path& dir) {
  return test::last_health_record(dir);
}

// received = accepted + rejected + foreign + overruns, from the JSON line.
void check_accounting(const json& h) {
  INFO(h.dump());
  CHECK(health_counter(h, "datagrams_received") ==
        health_counter(h, "packets_accepted") + health_counter(h, "packets_rejected") +
            health_counter(h, "foreign_datagrams") + health_counter(h, "ring_overruns"));
}

// No temporary or partial file anywhere under `dir`.
void check_no_temporary_files(const fs::path& dir) {
  for (const auto& entry : fs::recursive_directory_iterator(dir)) {
    const std::string name = entry.path().filename().string();
    INFO(entry.path().string());
    CHECK_FALSE(name.front() == '.');
    CHECK(entry.path().extension() != ".part");
    CHECK(entry.path().extension() != ".tmp");
  }
}

std::size_t pcd_points(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("POINTS ", 0) == 0) return std::stoul(line.substr(7));
  }
  return 0;
}

std::string pandarcapd() {
  return test::pandarcapd_command();
}

std::string pandarcapd_path() {
  return test::binary("pandarcapd").string();
}

}  // namespace

TEST_CASE("replay of the real capture: frames, pcap, health, accounting", "[daemon][threads]") {
  const auto capture = test::real_capture(kDualCapture);
  const auto calibration = test::real_capture(kCalibration);
  if (!capture || !calibration) return;
  test::ScratchDir dir("daemon-replay");
  const fs::path out = dir / "out";
  harness::ChildProcess daemon(
      pandarcapd_path(),
      {"--allow-root", "--replay", capture->string(), "--top-speed", "--calibration",
       calibration->string(), "--output-dir", out.string()},
      dir / "log.txt");
  const auto status = daemon.wait_exit(60s);
  INFO(daemon.log());
  REQUIRE(status == 0);

  // Health: every datagram accounted for, numbers as the capture holds them.
  const json h = last_health(out);
  REQUIRE(h.is_object());
  CHECK(health_counter(h, "datagrams_received") == 1439);
  CHECK(health_counter(h, "packets_accepted") == 1439);
  CHECK(health_counter(h, "packets_rejected") == 0);
  check_accounting(h);
  CHECK(health_counter(h, "frames_complete") == 2);
  CHECK(health_counter(h, "frames_written") + health_counter(h, "frames_fragment") ==
        health_counter(h, "frames_complete") + health_counter(h, "frames_partial"));
  CHECK(fs::exists(out / "health" / "pandarcap.prom"));

  // Frames: one PCD per frame; the complete ones hold the points the decoder verified.
  const auto pcds = files_ending(out / "frames", ".pcd");
  CHECK(pcds.size() == health_counter(h, "frames_written"));
  std::multiset<std::size_t> complete_points;
  for (const fs::path& pcd : pcds) {
    if (pcd.filename().string().find("_partial") == std::string::npos) {
      complete_points.insert(pcd_points(pcd));
    }
  }
  CHECK(complete_points == std::multiset<std::size_t>{56723, 56762});

  // Raw: the recording holds exactly the capture's payloads, in order, and tcpdump reads it.
  const auto pcaps = files_ending(out / "raw", ".pcap");
  REQUIRE(pcaps.size() == 1);
  CHECK(recorded(out / "raw") == payloads_of(*capture));
  CHECK(fs::exists(out / "raw" / "calibration.csv"));
  const auto tcpdump =
      test::run_command("tcpdump -nr '" + pcaps[0].string() + "' 2>/dev/null | wc -l");
  CHECK(std::stoul(tcpdump.out) == 1439);
  // Each packet keeps the destination the capture gives it (the recording host, port 2368).
  const auto to_host = test::run_command("tcpdump -nr '" + pcaps[0].string() +
                                         "' 2>/dev/null | grep -c '> 192.168.1.10.2368: UDP'");
  CHECK(std::stoul(to_host.out) == 1439);
  check_no_temporary_files(out);
  // A replayed packet's timestamp is its capture time: no latency is recorded.
  CHECK(h.at("latency").at("count") == 0);
  // The files the run made new count, with the CPU their creation took: the frames, the
  // recording, and the health's .prom (a new file each second, renamed into place), among others
  // (tests/test_io_seam.cpp counts them exactly).
  CHECK(health_counter(h, "files_created") > pcds.size() + pcaps.size());
  CHECK(health_counter(h, "file_create_cpu_us") > 0);
}

TEST_CASE("the real capture's sensor clock (2017) is not ok: offset gauge, degraded, journal",
          "[daemon][health][journal][threads]") {
  const auto capture = test::real_capture(kDualCapture);
  if (!capture) return;
  test::ScratchDir dir("daemon-clock-offset");
  // At a tenth of the recorded pace (0.4 s of packets) the replay lasts four seconds: the health
  // records of the run pass through the main thread, which logs the state's changes. (The
  // offset shows from the second record on: the decoder's counters reach the writer once a
  // second.)
  const auto replay = [&](const std::string& name, std::vector<std::string> extra) {
    std::vector<std::string> args{"--allow-root", "--replay",     capture->string(),    "--rate",
                                  "0.1",          "--output-dir", (dir / name).string()};
    args.insert(args.end(), extra.begin(), extra.end());
    harness::ChildProcess daemon(pandarcapd_path(), args, dir / (name + ".log"));
    const auto status = daemon.wait_exit(60s);
    INFO(daemon.log());
    CHECK(status == 0);
    return std::pair{last_health(dir / name), daemon.log()};
  };

  const auto [h, log] = replay("default", {});
  INFO(log);
  // The sensor's tail said 2017-09-06T16:19:46; the recording host's clock said 2023-01-11.
  const double expected = 1504714786.0 - 1673400149.0;
  REQUIRE(h.at("gauges").contains("sensor_clock_offset_seconds"));
  CHECK(std::abs(h.at("gauges").at("sensor_clock_offset_seconds").get<double>() - expected) < 2);
  CHECK(h.at("state") == "degraded");
  const std::string reason = h.at("reason");
  CHECK(reason.find("sensor clock off by 1686853") != std::string::npos);
  CHECK(reason.find(" s (behind the host): not synchronised?") != std::string::npos);
  CHECK(log.find("[warning] health: degraded: ") != std::string::npos);
  const std::string prom = harness::read_file(dir / "default" / "health" / "pandarcap.prom");
  CHECK(prom.find("pandarcap_sensor_clock_offset_seconds{sensor=\"pandar40p\"} -16868536") !=
        std::string::npos);

  // 0 turns the check off (for replays), and keeps the gauge.
  const auto [off, off_log] = replay("unchecked", {"--max-clock-offset", "0"});
  CHECK(off.at("reason").get<std::string>().find("sensor clock") == std::string::npos);
  CHECK(off.at("gauges").contains("sensor_clock_offset_seconds"));
}

TEST_CASE("the recording keeps each datagram's real destination address and port (IP_PKTINFO)",
          "[daemon][pcap][threads]") {
  const auto capture = test::real_capture(kDualCapture);
  if (!capture) return;
  const auto payloads = payloads_of(*capture);
  test::ScratchDir dir("daemon-destination");
  const fs::path out = dir / "out";
  const std::uint16_t port = harness::free_udp_port();
  // Bound to every address: the datagrams sent to 127.0.0.1 and to 127.0.0.2 both arrive, and
  // only the IP header says which address each was sent to.
  harness::ChildProcess daemon(pandarcapd_path(),
                               {"--allow-root", "--host-ip", "0.0.0.0", "--port",
                                std::to_string(port), "--output-dir", out.string()},
                               dir / "log.txt");
  REQUIRE(
      harness::wait_until([&] { return daemon.log().find("ready") != std::string::npos; }, 10s));
  const int fd = ::socket(AF_INET, SOCK_DGRAM, 0);
  REQUIRE(fd >= 0);
  const auto send_to = [&](const char* address, std::size_t count) {
    sockaddr_in to{};
    to.sin_family = AF_INET;
    to.sin_port = htons(port);
    REQUIRE(::inet_pton(AF_INET, address, &to.sin_addr) == 1);
    for (std::size_t i = 0; i < count; ++i) {
      REQUIRE(::sendto(fd, payloads[i].data(), payloads[i].size(), 0,
                       reinterpret_cast<const sockaddr*>(&to),
                       sizeof to) == static_cast<ssize_t>(payloads[i].size()));
    }
  };
  send_to("127.0.0.1", 30);
  send_to("127.0.0.2", 20);
  ::close(fd);
  REQUIRE(harness::wait_until(
      [&] { return health_counter(last_health(out), "datagrams_received") == 50; }, 20s));
  daemon.signal(SIGTERM);
  INFO(daemon.log());
  REQUIRE(daemon.wait_exit(10s) == 0);

  // tcpdump, an independent reader, sees what the wire carried.
  const auto pcaps = files_ending(out / "raw", ".pcap");
  REQUIRE(pcaps.size() == 1);
  const auto count = [&](const std::string& destination) {
    const auto r =
        test::run_command("tcpdump -nr '" + pcaps[0].string() + "' 2>/dev/null | grep -c '> " +
                          destination + "." + std::to_string(port) + ": UDP'");
    return std::stoi(r.out);
  };
  CHECK(count("127.0.0.1") == 30);
  CHECK(count("127.0.0.2") == 20);
  CHECK(count("0.0.0.0") == 0);
}

TEST_CASE("live UDP on loopback: foreign sender rejected, SIGTERM drains, all accounted",
          "[daemon][threads]") {
  const auto capture = test::real_capture(kDualCapture);
  if (!capture) return;
  const auto payloads = payloads_of(*capture);
  test::ScratchDir dir("daemon-live");
  const fs::path out = dir / "out";
  const std::uint16_t port = harness::free_udp_port();
  harness::ChildProcess daemon(
      pandarcapd_path(),
      {"--allow-root", "--host-ip", "127.0.0.1", "--port", std::to_string(port), "--sensor-ip",
       "127.0.0.1", "--output-dir", out.string()},
      dir / "log.txt");
  // Ready once the first health file is there (written before the threads start).
  REQUIRE(harness::wait_until([&] { return fs::exists(out / "health" / "pandarcap.prom"); }, 10s));
  REQUIRE(
      harness::wait_until([&] { return daemon.log().find("ready") != std::string::npos; }, 10s));

  const std::vector<std::vector<std::uint8_t>> foreign(25, payloads.front());
  harness::send_udp("127.0.0.1", port, payloads);
  harness::send_udp("127.0.0.2", port, foreign);
  const std::uint64_t sent = payloads.size() + foreign.size();
  // Wait until the daemon has seen everything (or the kernel reports having dropped the rest).
  const bool all_seen = harness::wait_until(
      [&] {
        const json h = last_health(out);
        return health_counter(h, "datagrams_received") + health_counter(h, "kernel_drops") >= sent;
      },
      20s);
  INFO(daemon.log());
  REQUIRE(all_seen);

  const auto stop_started = std::chrono::steady_clock::now();
  daemon.signal(SIGTERM);
  const auto status = daemon.wait_exit(10s);
  const auto stop_took = std::chrono::steady_clock::now() - stop_started;
  REQUIRE(status == 0);
  CHECK(stop_took < 2s);

  const json h = last_health(out);
  INFO(h.dump());
  CHECK(health_counter(h, "datagrams_received") + health_counter(h, "kernel_drops") == sent);
  CHECK(health_counter(h, "foreign_datagrams") == foreign.size());
  CHECK(health_counter(h, "packets_rejected") == 0);
  check_accounting(h);
  // What was accepted was recorded, byte for byte (no kernel drops expected on loopback; if there
  // were any, the recording is a prefix-preserving subset).
  const auto raw = recorded(out / "raw");
  CHECK(raw.size() == health_counter(h, "packets_accepted"));
  if (health_counter(h, "kernel_drops") == 0) CHECK(raw == payloads);
  // The frame in progress at SIGTERM was finished as partial, and nothing was left half-written.
  CHECK(files_ending(out / "frames", ".pcd").size() == health_counter(h, "frames_written"));
  CHECK(health_counter(h, "frames_written") >= 3);
  check_no_temporary_files(out);
}

TEST_CASE("SIGHUP starts a new pcap without losing a packet", "[daemon][threads]") {
  const auto capture = test::real_capture(kDualCapture);
  if (!capture) return;
  const auto payloads = payloads_of(*capture);
  const std::vector<std::vector<std::uint8_t>> first(payloads.begin(), payloads.begin() + 700);
  const std::vector<std::vector<std::uint8_t>> second(payloads.begin() + 700, payloads.end());
  test::ScratchDir dir("daemon-hup");
  const fs::path out = dir / "out";
  const std::uint16_t port = harness::free_udp_port();
  harness::ChildProcess daemon(pandarcapd_path(),
                               {"--allow-root", "--host-ip", "127.0.0.1", "--port",
                                std::to_string(port), "--output-dir", out.string()},
                               dir / "log.txt");
  REQUIRE(
      harness::wait_until([&] { return daemon.log().find("ready") != std::string::npos; }, 10s));
  const auto seen = [&](std::uint64_t n) {
    return harness::wait_until(
        [&] {
          const json h = last_health(out);
          return health_counter(h, "pcap_packets_written") + health_counter(h, "kernel_drops") >= n;
        },
        20s);
  };
  harness::send_udp("127.0.0.1", port, first);
  REQUIRE(seen(first.size()));
  daemon.signal(SIGHUP);
  REQUIRE(
      harness::wait_until([&] { return daemon.log().find("SIGHUP") != std::string::npos; }, 10s));
  harness::send_udp("127.0.0.1", port, second);
  REQUIRE(seen(payloads.size()));
  daemon.signal(SIGTERM);
  REQUIRE(daemon.wait_exit(10s) == 0);
  const json h = last_health(out);
  INFO(daemon.log());
  CHECK(files_ending(out / "raw", ".pcap").size() == 2);
  if (health_counter(h, "kernel_drops") == 0) CHECK(recorded(out / "raw") == payloads);
  check_no_temporary_files(out);
}

TEST_CASE("pandarcapd --simulate runs the live path with no sensor",
          "[daemon][realtime][threads]") {
  test::ScratchDir dir("daemon-simulate");
  const fs::path out = dir / "out";
  harness::ChildProcess daemon(
      pandarcapd_path(),
      {"--allow-root", "--simulate", "--duration", "4", "--output-dir", out.string()},
      dir / "log.txt");
  const auto status = daemon.wait_exit(30s);
  INFO(daemon.log());
  REQUIRE(status == 0);
  const json h = last_health(out);
  INFO(h.dump());
  // 4 s of dual return at 600 RPM is ~14400 packets; allow for start-up and scheduling. Under a
  // sanitizer on a busy machine the simulated sensor itself (a thread of the daemon, instrumented
  // too) may send fewer: then what counts is that every one is accounted for (below).
  CHECK(health_counter(h, "packets_accepted") > (test::kSlowBuild ? 1000u : 10000u));
  CHECK(health_counter(h, "packets_rejected") == 0);
  check_accounting(h);
  CHECK(health_counter(h, "frames_complete") >= 10);
  // Every datagram recorded (sanitizer builds: or counted as not recorded, see kSlowBuild;
  // ThreadSanitizer's: or overrun by the ring, see check_ring_overruns).
  const std::uint64_t overruns = test::check_ring_overruns(h);
  CHECK(health_counter(h, "pcap_packets_written") +
            (test::kSlowBuild ? health_counter(h, "pcap_packets_not_recorded") : 0) + overruns ==
        health_counter(h, "datagrams_received"));
  CHECK(health_records(out).size() >= 2);  // one per second, plus the final one
  // Every packet that reached the decoder has a receive-to-decoded latency; at the sensor's
  // rate it is well under a second, and the percentiles are ordered.
  const json& latency = h.at("latency");
  CHECK(latency.at("count") ==
        health_counter(h, "packets_accepted") + health_counter(h, "packets_rejected"));
  CHECK(latency.at("p50_us").get<double>() > 0);
  CHECK(latency.at("p50_us").get<double>() <= latency.at("p99_us").get<double>());
  CHECK(latency.at("p99_us").get<double>() <= latency.at("max_us").get<double>());
  if (!test::kSlowBuild) CHECK(latency.at("max_us").get<double>() < 1e6);
    // The receive, decode and writer loops allocate nothing once warm (2 s), with frames, pcap
    // and both health files being written. Sanitizer builds keep their own allocator, and then the
    // daemon does not report the count at all.
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  CHECK_FALSE(h.at("counters").contains("hot_path_allocations"));
#else
  const json& allocations = h.at("counters").at("hot_path_allocations_by_thread");
  CHECK(allocations.at("receive") == 0);
  CHECK(allocations.at("decode") == 0);
  CHECK(allocations.at("writer") == 0);
  CHECK(h.at("counters").at("hot_path_allocations") == 0);
#endif
  check_no_temporary_files(out);
}

TEST_CASE("pandarcapd --decoder: every target this CPU runs writes the scalar reference's frames",
          "[daemon][simd][threads]") {
  const auto capture = test::real_capture(kDualCapture);
  const auto calibration = test::real_capture(kCalibration);
  if (!capture || !calibration) return;
  test::ScratchDir dir("daemon-decoder");
  // file name -> POINTS, per target
  auto run = [&](const std::string& target) {
    const fs::path out = dir / target;
    const auto result =
        test::run_command(pandarcapd() + " --replay '" + capture->string() +
                          "' --top-speed --calibration '" + calibration->string() + "' --decoder " +
                          target + " --output-dir '" + out.string() + "' 2>&1");
    INFO(result.out);
    REQUIRE(result.exit_code == 0);
    // The log names the decoder that ran: what was asked for, or what auto resolved to.
    const std::string ran =
        target == "auto" ? std::string(to_string(best_decoder_target())) : target;
    CHECK(result.out.find("decoder: " + ran) != std::string::npos);
    std::map<std::string, std::size_t> frames;
    for (const fs::path& pcd : files_ending(out / "frames", ".pcd")) {
      frames[pcd.filename().string()] = pcd_points(pcd);
    }
    return frames;
  };
  const auto reference = run("scalar");
  // 2 complete + 2 partial; the other 2 partials are slivers at the stream's start and end
  // (frames_fragment), not written.
  REQUIRE(reference.size() == 4);
  std::vector<std::string> targets{"auto"};
  for (const DecoderTarget target : supported_decoder_targets()) {
    if (target != DecoderTarget::kScalar) targets.emplace_back(to_string(target));
  }
  for (const std::string& target : targets) {
    INFO("decoder " << target);
    CHECK(run(target) == reference);
  }
}

TEST_CASE("replay waits for free arenas: two arenas at top speed still write every frame",
          "[daemon][threads]") {
  const auto capture = test::real_capture(kDualCapture);
  if (!capture) return;
  test::ScratchDir dir("daemon-replay-arenas");
  const fs::path config = dir / "two-arenas.toml";
  std::ofstream(config) << "[arenas]\ncount = 2\npackets_per_frame = 64\n";
  const fs::path out = dir / "out";
  const auto result = test::run_command(pandarcapd() + " -c '" + config.string() + "' --replay '" +
                                        capture->string() + "' --top-speed --output-dir '" +
                                        out.string() + "' 2>&1");
  INFO(result.out);
  REQUIRE(result.exit_code == 0);
  const json h = last_health(out);
  CHECK(health_counter(h, "frames_dropped_no_arena") == 0);
  CHECK(health_counter(h, "pcap_packets_not_recorded") == 0);
  CHECK(health_counter(h, "frames_written") + health_counter(h, "frames_fragment") == 6);
  CHECK(health_counter(h, "frames_written") == 4);
  CHECK(files_ending(out / "frames", ".pcd").size() == 4);
  CHECK(recorded(out / "raw").size() == 1439);
}

TEST_CASE("pandarcapd --decoder naming a target this machine cannot run exits 78, no fallback",
          "[daemon][simd][config][threads]") {
  const std::vector<DecoderTarget> supported = supported_decoder_targets();
  for (const char* name : {"sse4", "avx2", "avx512", "neon", "sve", "sve2"}) {
    const DecoderTarget target = *decoder_target_from_string(name);
    if (std::find(supported.begin(), supported.end(), target) != supported.end()) continue;
    test::ScratchDir dir("daemon-decoder-missing");
    const auto result =
        test::run_command(pandarcapd() + " --simulate --duration 1 --decoder " + name +
                          " --output-dir '" + (dir / "out").string() + "' 2>&1");
    INFO(result.out);
    CHECK(result.exit_code == 78);
    CHECK(result.out.find(std::string("decoder '") + name + "'") != std::string::npos);
    CHECK(result.out.find("supported: scalar") != std::string::npos);
    CHECK_FALSE(fs::exists(dir / "out" / "frames"));
  }
}

TEST_CASE("a bad configuration exits 78 with file:line:col", "[daemon][config]") {
  test::ScratchDir dir("daemon-config");
  const fs::path config = dir / "bad.toml";
  std::ofstream(config) << "[sensor]\ndata_port = 2368\nmax_range = \"far\"\n";
  const auto bad =
      test::run_command(pandarcapd() + " --check-config -c '" + config.string() + "' 2>&1");
  CHECK(bad.exit_code == 78);
  CHECK(bad.out.find(config.string() + ":3:") != std::string::npos);
  // A running daemon refuses it the same way.
  const auto run = test::run_command(pandarcapd() + " -c '" + config.string() + "' --output-dir '" +
                                     (dir / "out").string() + "' 2>&1");
  CHECK(run.exit_code == 78);
  const fs::path good = dir / "good.toml";
  std::ofstream(good) << "[sensor]\ndata_port = 2369\n";
  const auto ok = test::run_command(pandarcapd() + " --check-config -c '" + good.string() + "'");
  CHECK(ok.exit_code == 0);
  const auto printed = test::run_command(pandarcapd() + " --print-config -c '" + good.string() +
                                         "' --max-range 150");
  CHECK(printed.exit_code == 0);
  CHECK(printed.out.find("data_port = 2369") != std::string::npos);
  CHECK(printed.out.find("max_range = 150") != std::string::npos);
}

namespace {

// A pcap of simulated 1266-byte packets (with UDP sequence) at the given record times.
fs::path write_capture(const fs::path& path, const std::vector<std::int64_t>& times_ns) {
  SyntheticSensorConfig config;
  config.udp_sequence = true;
  SyntheticSensor sensor(config);
  std::array<std::uint8_t, kMaxPacketBytes> packet{};
  PcapWriter pcap(path.string());
  for (const std::int64_t t : times_ns) {
    const std::size_t size = sensor.next(packet);
    pcap.write({packet.data(), size}, t, Endpoint{0xC0A801C9, 2368}, Endpoint{0x7F000001, 2368});
  }
  pcap.close();
  return path;
}

}  // namespace

TEST_CASE("replay: a datagram the file holds only part of is rejected, not decoded as shorter",
          "[daemon][replay][threads]") {
  test::ScratchDir dir("daemon-snapped");
  const fs::path capture = write_capture(
      dir / "snapped.pcap",
      {1'700'000'000'000'000'000, 1'700'000'000'000'278'000, 1'700'000'000'000'556'000});
  // Cut the second record to 1262 bytes of UDP payload (snaplen): its headers still say 1266.
  std::string bytes = harness::read_file(capture);
  const std::size_t record = 24 + 16 + 42 + 1266;  // start of the second record header
  const std::uint32_t kept = 42 + 1262;
  std::memcpy(&bytes[record + 8], &kept, 4);  // incl_len (native order, as written)
  bytes.erase(record + 16 + kept, 4);
  std::ofstream(capture, std::ios::binary | std::ios::trunc) << bytes;

  const auto run = test::run_command(pandarcapd() + " --replay '" + capture.string() +
                                     "' --output-dir '" + (dir / "out").string() + "' 2>&1");
  INFO(run.out);
  REQUIRE(run.exit_code == 0);
  const json h = last_health(dir / "out");
  CHECK(health_counter(h, "datagrams_received") == 3);
  CHECK(health_counter(h, "packets_accepted") == 2);
  CHECK(health_counter(h, "packets_rejected") == 1);
  CHECK(h["counters"]["rejects"].value("bad_length", 0) == 1);
  CHECK(health_counter(h, "truncated_datagrams") == 1);
  check_accounting(h);
}

TEST_CASE("replay --rate: timestamps decades apart neither overflow nor hold SIGTERM",
          "[daemon][replay][threads]") {
  test::ScratchDir dir("daemon-rate-gap");
  // 1970, then 2036: at --rate 0.001 the wait would be 2.1e21 ns, far past int64. (Classic pcap
  // times past 2038 come back from libpcap as negative: its seconds field is signed.)
  const fs::path capture =
      write_capture(dir / "gap.pcap", {1'000'000'000, 2'100'000'000'000'000'000});
  harness::ChildProcess daemon(pandarcapd_path(),
                               {"--allow-root", "--replay", capture.string(), "--rate", "0.001",
                                "--output-dir", (dir / "out").string()},
                               dir / "log.txt");
  // The first packet is through (health written) while the replay waits for the second.
  REQUIRE(harness::wait_until(
      [&] {
        const json h = last_health(dir / "out");
        return health_counter(h, "packets_accepted") == 1;
      },
      15s));
  daemon.signal(SIGTERM);
  INFO(daemon.log());
  CHECK(daemon.wait_exit(5s) == 0);
  CHECK(health_counter(last_health(dir / "out"), "packets_accepted") == 1);
}

TEST_CASE("a stalled writer: frames drop and are counted, the receiver never blocks, RSS flat",
          "[daemon][reliability][realtime][threads]") {
  test::ScratchDir dir("daemon-slow-writer");
  const fs::path out = dir / "out";
  const fs::path stall = dir / "stall-writer";
  harness::ChildProcess daemon(
      pandarcapd_path(), {"--allow-root", "--simulate", "--output-dir", out.string()},
      dir / "log.txt", {"PANDARCAP_TEST_STALL_WRITER_FILE=" + stall.string()});
  // Warm: every arena has been filled and written at least once (10 frames a second, 4 arenas).
  REQUIRE(harness::wait_until(
      [&] { return health_counter(last_health(out), "frames_written") >= 8; }, 15s));
  const std::uint64_t rss_before = harness::process_memory_bytes(daemon.pid(), "VmRSS");
  // Usually 0, but a sanitizer build on a busy machine can lose a frame while warming up: the
  // stall's drops are counted from here.
  const std::uint64_t dropped_before = health_counter(last_health(out), "frames_dropped_no_arena");

  // The scenario: the writer stops (a disk that hangs) for three seconds, thirty frames' worth.
  // The decoder may be up to a ring's length (about a second) behind the stream on a busy
  // machine under a sanitizer, so it still cuts twenty of them during the stall: 4 into the
  // arenas, the rest dropped.
  REQUIRE(test::stall_writer(daemon, stall, 5s));
  const auto stalled_at = std::chrono::steady_clock::now();
  while (std::chrono::steady_clock::now() - stalled_at < 3s)
    CHECK(daemon.wait_exit(100ms) == std::nullopt);  // still running, the receiver included
  const std::uint64_t rss_stalled = harness::process_memory_bytes(daemon.pid(), "VmRSS");
  fs::remove(stall);
  REQUIRE(harness::wait_until(
      [&] { return health_counter(last_health(out), "frames_dropped_no_arena") > dropped_before; },
      10s));

  daemon.signal(SIGTERM);
  INFO(daemon.log());
  REQUIRE(daemon.wait_exit(10s) == 0);
  const json h = last_health(out);
  INFO(h.dump());
  // Drops only as counted frame drops: nothing lost before the decoder.
  CHECK(health_counter(h, "frames_dropped_no_arena") >= dropped_before + 10);
  CHECK(health_counter(h, "kernel_drops") == 0);
  const std::uint64_t overruns = test::check_ring_overruns(h);
  CHECK(health_counter(h, "packets_accepted") + overruns ==
        health_counter(h, "datagrams_received"));
  check_accounting(h);
  // Every frame that had an arena was written; the dropped ones are exactly the counted ones.
  CHECK(health_counter(h, "frames_written") + health_counter(h, "frames_fragment") ==
        health_counter(h, "frames_complete") + health_counter(h, "frames_partial"));
  CHECK(files_ending(out / "frames", ".pcd").size() == health_counter(h, "frames_written"));
  // Fixed memory: the stall grew nothing (the queues and arenas are preallocated).
  CHECK(rss_stalled <= rss_before + (2u << 20));
  // Nor did saying so: the health's reason ("N frames dropped (no free arena)"), first written
  // long after the loops are warm, allocated nothing (counted where allocations can be).
  if (h.at("counters").contains("hot_path_allocations_by_thread")) {
    const json& allocations = h.at("counters").at("hot_path_allocations_by_thread");
    CHECK(allocations.at("writer") == 0);
    CHECK(allocations.at("decode") == 0);
  }
}
