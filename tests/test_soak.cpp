// Soak: pandarcapd at ten dual-return sensors' rate (36,000 packets/s) with every output on and
// rotation active, for PANDARCAP_SOAK_SECONDS (default 60; docs/reliability.md gives the
// 10-minute command). Zero loss at any stage, resident memory grows by less than 1 % after warm-up,
// the same file descriptors at the end as after warm-up, and a health record for every second.
//
// Hidden from a plain run ("[.soak]"); CI runs it once, alone, in the release build (tests/
// CMakeLists.txt: soak_60s). Sanitizer builds are several times slower and would measure
// themselves, not the daemon.
//
// The recordings go to a tmpfs of the daemon's own (a private mount namespace): every file is
// synced before its final name, and at ten sensors' rate that is 245 MB/s the disk must take,
// more than a CI machine's disk does. The soak measures the daemon's steadiness; what the syncs
// cost on a real disk is measured at the sensor's rate (docs/performance.md, "Durable files").
#include <signal.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "bench/child_process.hpp"
#include "bench/udp_traffic.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
using namespace std::chrono_literals;
using nlohmann::json;
namespace fs = std::filesystem;
using test::health_counter;
using test::open_descriptors;

TEST_CASE(
    "soak: 10 x a dual-return sensor, all outputs and rotation: zero loss, flat memory and "
    "descriptors, every second in the health record",
    "[.soak]") {
  const char* seconds_env = std::getenv("PANDARCAP_SOAK_SECONDS");
  const double seconds = seconds_env != nullptr ? std::atof(seconds_env) : 60.0;
  REQUIRE(seconds >= 20);
  test::ScratchDir dir("daemon-soak");
  const fs::path out = dir / "out";
  const fs::path health = dir / "health";  // on the real disk: the test reads it throughout
  fs::create_directories(out);
  const std::uint16_t port = harness::free_udp_port();
  // Rotation every 5 s and bounded retention, so the tmpfs holds about 1.5 GB at most.
  const fs::path config = dir / "soak.toml";
  std::ofstream(config) << "[sensor]\nhost_ip = \"127.0.0.1\"\nsensor_ip = \"127.0.0.1\"\n"
                        << "data_port = " << port << "\n"
                        << "[output]\npcap_rotate_seconds = 5\npcap_max_files = 4\n"
                           "frames_max_files = 50\n[arenas]\ncount = 16\n[health]\ndirectory = \""
                        << health.string() << "\"\njsonl_rotate_bytes = 0\n";
  const std::vector<std::string> daemon_args = {test::binary("pandarcapd").string(),
                                                "--allow-root",
                                                "-c",
                                                config.string(),
                                                "--output-dir",
                                                out.string()};
  // As root directly, otherwise in a user namespace where this user is root; unshare execs sh,
  // which mounts the tmpfs and execs pandarcapd: one process, one pid.
  const std::string userns = ::geteuid() == 0 ? "" : "--user --map-root-user ";
  const bool own_tmpfs =
      test::run_command("unshare " + userns + "--mount true 2>/dev/null").exit_code == 0;
  std::vector<std::string> args;
  if (::geteuid() != 0) args = {"--user", "--map-root-user"};
  for (const char* arg : {"--mount", "--propagation", "private", "--", "/bin/sh", "-c",
                          "mount -t tmpfs -o size=3g pandarcap-soak \"$0\" && exec \"$@\""})
    args.emplace_back(arg);
  args.push_back(out.string());
  args.insert(args.end(), daemon_args.begin(), daemon_args.end());
  if (!own_tmpfs) {
    if (std::getenv("CI") != nullptr) FAIL("CI runs as root: a mount namespace must be possible");
    WARN("no mount namespace here: the recordings go to the disk, whose bandwidth may not hold");
    args.assign(daemon_args.begin() + 1, daemon_args.end());
  }
  harness::ChildProcess daemon(
      own_tmpfs ? fs::path("/usr/bin/unshare") : fs::path(daemon_args.front()), args,
      dir / "log.txt");
  // The recordings as the daemon sees them (its mount namespace, through /proc).
  const fs::path view =
      own_tmpfs ? fs::path("/proc") / std::to_string(daemon.pid()) / "root" / out.relative_path()
                : out;
  INFO(daemon.log());
  REQUIRE(
      harness::wait_until([&] { return daemon.log().find("ready:") != std::string::npos; }, 20s));

  const auto source = bench::TrafficSource::synthetic(SyntheticSensorConfig{});
  bench::GeneratorOptions traffic;
  traffic.port = port;
  traffic.rate_pps = 36000;
  traffic.seconds = seconds;
  // Memory and descriptors after warm-up (10 s in), and again just before the end, measured from
  // a thread while the generator runs on this one.
  std::uint64_t rss_warm = 0, rss_end = 0;
  std::size_t fds_warm = 0, fds_end = 0;
  std::thread sampler([&] {
    const auto start = std::chrono::steady_clock::now();
    std::this_thread::sleep_until(start + 10s);  // sampling times, not synchronisation
    rss_warm = harness::process_memory_bytes(daemon.pid(), "VmRSS");
    fds_warm = open_descriptors(daemon.pid());
    std::this_thread::sleep_until(start + std::chrono::duration<double>(seconds - 2));
    rss_end = harness::process_memory_bytes(daemon.pid(), "VmRSS");
    fds_end = open_descriptors(daemon.pid());
  });
  const bench::GeneratorResult sent = bench::run_generator(source, traffic);
  sampler.join();
  INFO("sent " << sent.sent << " at " << sent.achieved_pps << " packets/s");
  CHECK(sent.achieved_pps >= 0.99 * traffic.rate_pps);

  REQUIRE(harness::wait_until(
      [&] {
        const json last = test::last_health_record(dir.path());
        return !last.is_null() &&
               health_counter(last, "datagrams_received") + health_counter(last, "kernel_drops") >=
                   sent.sent;
      },
      20s));
  // Rotation was active (seen before the daemon, and with it its tmpfs, is gone).
  CHECK(test::files_ending(view / "raw", ".pcap").size() >= 2);
  daemon.signal(SIGTERM);
  CHECK(daemon.wait_exit(30s) == 0);

  const std::vector<json> records = test::health_records(dir.path());
  REQUIRE_FALSE(records.empty());
  const json& last = records.back();
  INFO(last.dump());
  // Zero loss, at every stage.
  CHECK(health_counter(last, "packets_accepted") == sent.sent);
  CHECK(health_counter(last, "kernel_drops") == 0);
  CHECK(health_counter(last, "ring_overruns") == 0);
  CHECK(health_counter(last, "sequence_lost") == 0);
  CHECK(health_counter(last, "packets_rejected") == 0);
  CHECK(health_counter(last, "pcap_packets_not_recorded") == 0);
  CHECK(health_counter(last, "frames_dropped_no_arena") == 0);
  CHECK(health_counter(last, "write_errors") == 0);
  CHECK(health_counter(last, "pcap_packets_written") == sent.sent);
  CHECK(health_counter(last, "frames_written") + health_counter(last, "frames_fragment") ==
        health_counter(last, "frames_complete") + health_counter(last, "frames_partial"));
  // Flat: memory within 1 % of its warm size, the same descriptors (±2: a frame or a pcap may be
  // mid-open at either count).
  INFO("RSS " << rss_warm << " -> " << rss_end << " bytes, descriptors " << fds_warm << " -> "
              << fds_end);
  REQUIRE(rss_warm > 0);
  CHECK(static_cast<double>(rss_end) <= 1.01 * static_cast<double>(rss_warm));
  CHECK(fds_end <= fds_warm + 2);
  CHECK(fds_end + 2 >= fds_warm);
  // Every second: one record a second from start to end (the final one may follow sooner).
  CHECK(records.size() + 2 >= static_cast<std::size_t>(seconds));
  test::check_record_spacing(records, 0.5);
  // Retention and rotation at every step allocate nothing once warm, on any hot thread
  // (sanitizer builds count nothing).
  if (!test::kSanitizerBuild) {
    CHECK(last.at("counters").at("hot_path_allocations") == 0);
    for (const char* thread : {"receive", "decode", "writer"}) {
      INFO(thread);
      CHECK(last.at("counters").at("hot_path_allocations_by_thread").at(thread) == 0);
    }
  }
}
