// The host's wall clock jumps (an administrator, NTP stepping, a GPS fix): pandarcapd's pcap
// rotation and its once-a-second health run on CLOCK_MONOTONIC, so neither notices. The jump is
// made by an LD_PRELOAD shim (tests/clock_shift_preload.cpp) that moves CLOCK_REALTIME for the
// daemon alone: an hour forward, then an hour behind where it started.
#include <signal.h>

#include <catch2/catch.hpp>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "bench/child_process.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
using namespace std::chrono_literals;
using nlohmann::json;
namespace fs = std::filesystem;
using test::health_records;

namespace {

// The daemon's wall clock minus this process's, in seconds, from its newest health record.
double shift_seen_s(const fs::path& out) {
  const auto records = health_records(out);
  if (records.empty()) return 0;
  const auto now = std::chrono::system_clock::now().time_since_epoch();
  const double ours = std::chrono::duration<double>(now).count();
  return records.back()["unix_time_ns"].get<double>() / 1e9 - ours;
}

// LD_PRELOAD for the daemon: the clock shim, then what this process already preloads (the thread
// census, in the release job).
std::string daemon_preload() {
  std::string preload = PANDARCAP_CLOCK_SHIFT_PRELOAD;
  if (const char* ours = std::getenv("LD_PRELOAD"); ours != nullptr && *ours != '\0') {
    preload += ':';
    preload += ours;
  }
  return preload;
}

}  // namespace

TEST_CASE("a wall-clock jump on the host disturbs neither pcap rotation nor per-second health",
          "[daemon][reliability][time][threads]") {
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  // A preloaded library ahead of the sanitizer runtime is refused by it; the release job runs
  // this test.
  WARN("sanitizer build: the LD_PRELOAD clock shim cannot be loaded; covered by the release job");
  return;
#endif
  test::ScratchDir dir("daemon-wall-clock");
  const fs::path out = dir / "out";
  const fs::path shift = dir / "clock-shift";
  std::ofstream(shift) << "0\n";
  const fs::path config = dir / "clock.toml";
  std::ofstream(config) << "[output]\npcap_rotate_seconds = 2\n";
  harness::ChildProcess daemon(
      test::binary("pandarcapd"),
      {"--allow-root", "-c", config.string(), "--simulate", "--output-dir", out.string()},
      dir / "log.txt",
      {"LD_PRELOAD=" + daemon_preload(), "PANDARCAP_TEST_CLOCK_SHIFT_FILE=" + shift.string()});
  INFO(daemon.log());
  const auto lines = [&] { return health_records(out).size(); };
  REQUIRE(harness::wait_until([&] { return lines() >= 2; }, 20s));

  // An hour forward: the daemon's health records say so (the shim works) ...
  std::ofstream(shift) << "3600\n";
  REQUIRE(harness::wait_until([&] { return std::abs(shift_seen_s(out) - 3600) < 5; }, 5s));
  std::size_t at = lines();
  REQUIRE(harness::wait_until([&] { return lines() >= at + 3; }, 10s));
  // ... then an hour behind where it began.
  std::ofstream(shift) << "-3600\n";
  REQUIRE(harness::wait_until([&] { return std::abs(shift_seen_s(out) + 3600) < 5; }, 5s));
  at = lines();
  REQUIRE(harness::wait_until([&] { return lines() >= at + 3; }, 10s));
  daemon.signal(SIGTERM);
  REQUIRE(daemon.wait_exit(20s) == 0);

  // One health record a second throughout, by the monotonic uptime: none skipped, none doubled.
  const auto records = health_records(out);
  const double uptime = records.back()["gauges"]["uptime_seconds"].get<double>();
  INFO(records.size() << " records over " << uptime << " s");
  test::check_record_spacing(records, 0.5);
  CHECK(records.size() + 1 >= static_cast<std::size_t>(uptime));
  CHECK(records.size() <= static_cast<std::size_t>(uptime) + 2);
  // A new pcap every 2 s of monotonic time, whatever the wall clock did (a jump of an hour would
  // otherwise rotate at once, or never).
  std::size_t pcaps = 0;
  for (const auto& entry : fs::directory_iterator(out / "raw"))
    pcaps += entry.path().extension() == ".pcap" ? 1 : 0;
  INFO(pcaps << " pcaps");
  CHECK(pcaps + 1 >= static_cast<std::size_t>(uptime / 2));
  CHECK(pcaps <= static_cast<std::size_t>(uptime / 2) + 2);
  // Still capturing normally at the end.
  CHECK(records.back()["counters"]["packets_accepted"].get<std::uint64_t>() > 0);
  CHECK(records.back()["counters"]["kernel_drops"].get<std::uint64_t>() == 0);
}
