// Power lost under a running daemon (docs/reliability.md, "Power cut"): its output directory on an
// ext4 image of the test's own, shut down at a random moment as a power cut leaves a disk
// (FS_IOC_SHUTDOWN, nothing of data or journal flushed after that instant: xfstests' godown),
// then mounted again and the daemon started again. Root only (CI runs as root).
//
// What must hold, whatever the moment:
//   - every file that had its final name is whole: each PCD frame's body is POINTS x the point's
//     size, each recording (pcap, pcap.zst, MCAP) reads to its end, each has its sidecars;
//   - raw/calibration.csv and raw/sensor.json are whole;
//   - the next start finishes every .part, and the recording open at the cut then holds the
//     packets received up to output.sync_interval_seconds + 1.5 s before the cut.
#include <signal.h>

#include <catch2/catch.hpp>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "bench/child_process.hpp"
#include "support/loop_file_system.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
using namespace std::chrono_literals;
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

constexpr double kSyncIntervalSeconds = 2.0;  // output.sync_interval_seconds' default

std::int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

// A PCD file's POINTS x point size against the bytes after its DATA line: equal when whole.
void check_pcd_whole(const fs::path& file) {
  INFO(file.string());
  const std::string bytes = harness::read_file(file);
  const std::size_t data = bytes.find("\nDATA binary\n");
  INFO(bytes.size() << " bytes, beginning " << bytes.substr(0, 200));
  REQUIRE(data != std::string::npos);
  std::istringstream header(bytes.substr(0, data));
  std::vector<std::uint64_t> sizes, counts;
  std::uint64_t points = 0;
  for (std::string line; std::getline(header, line);) {
    std::istringstream words(line);
    std::string key;
    words >> key;
    std::vector<std::uint64_t>* into = key == "SIZE" ? &sizes : key == "COUNT" ? &counts : nullptr;
    for (std::uint64_t v; into != nullptr && words >> v;)
      into->push_back(v);
    if (key == "POINTS") words >> points;
  }
  REQUIRE(sizes.size() == counts.size());
  std::uint64_t point_bytes = 0;
  for (std::size_t i = 0; i < sizes.size(); ++i)
    point_bytes += sizes[i] * counts[i];
  CHECK(points > 0);
  CHECK(bytes.size() - (data + 13) == points * point_bytes);
}

// pandarcap-inspect --json of a recording: read to its end; the last packet's receive time (0:
// none).
std::int64_t check_recording_whole(const fs::path& file, std::uint64_t& packets) {
  INFO(file.string());
  const test::CommandResult r = test::run_command(test::binary("pandarcap-inspect").string() +
                                                  " --json '" + file.string() + "' 2>/dev/null");
  CHECK(r.exit_code == 0);
  const json report = json::parse(r.out, nullptr, false);
  REQUIRE_FALSE(report.is_discarded());
  CHECK(report.at("summary").at("capture_status") == "end");
  const json& list = report.at("packets");
  packets = list.size();
  return list.empty() ? 0 : list.back().at("record_time_ns").get<std::int64_t>();
}

struct Mode {
  const char* name;
  std::vector<std::string> args;
  const char* directory;  // where the recording whose .part is checked goes
  const char* suffix;     // its final name's end
  const char* file_system = "ext4";
};

// One cut at `cut_after` after the daemon said ready.
void power_cut_trial(const Mode& mode, std::chrono::milliseconds cut_after) {
  INFO(mode.name << " on " << mode.file_system << ", cut " << cut_after.count()
                 << " ms after ready");
  test::ScratchDir dir(std::string("power-cut-") + mode.name);
  // Room for 10 s of every output (frames, pcap and MCAP: ~35 MB/s): no write is refused here.
  test::LoopFileSystem disk(dir / "disk.img", dir / "mnt", 1ull << 30, mode.file_system);
  if (!disk.available()) return;
  const fs::path out = disk.mount_point() / "o";
  std::vector<std::string> args{"--allow-root", "--simulate", "--output-dir", out.string()};
  args.insert(args.end(), mode.args.begin(), mode.args.end());

  std::int64_t cut_ns = 0;
  {
    harness::ChildProcess daemon(test::binary("pandarcapd"), args, dir / "log-cut.txt");
    REQUIRE(
        harness::wait_until([&] { return daemon.log().find("ready:") != std::string::npos; }, 30s));
    // The moment of the fault, chosen at random: a deadline, not a wait for the daemon.
    std::this_thread::sleep_for(cut_after);
    cut_ns = now_ns();
    REQUIRE(disk.shut_down());
    daemon.signal(SIGTERM);
    // It ends, however its files fail (EIO from now on), and is not killed by a signal.
    const std::optional<int> status = daemon.wait_exit(60s);
    INFO(daemon.log());
    REQUIRE(status.has_value());
    CHECK(*status >= 0);
  }
  REQUIRE(disk.remount());
  INFO(harness::read_file(dir / "log-cut.txt"));

  // Whatever had its final name at the cut is whole.
  std::size_t frames = 0;
  for (const fs::path& f : test::files_ending(out / "frames", ".pcd")) {
    check_pcd_whole(f);
    ++frames;
  }
  if (cut_after >= 2500ms) CHECK(frames > 0);
  for (const char* name : {"calibration.csv", "sensor.json"}) {
    INFO(name);
    REQUIRE(fs::exists(out / "raw" / name));
    CHECK(fs::file_size(out / "raw" / name) > 0);
  }
  std::vector<fs::path> finished;
  for (const char* suffix : {".pcap", ".pcap.zst"}) {
    for (const fs::path& f : test::files_ending(out / "raw", suffix))
      finished.push_back(f);
  }
  for (const fs::path& f : test::files_ending(out / "mcap", ".mcap"))
    finished.push_back(f);
  for (const fs::path& f : finished) {
    std::uint64_t packets = 0;
    check_recording_whole(f, packets);
  }
  const std::vector<fs::path> parts = test::files_ending(out / mode.directory, ".part");

  // The next start finishes the .part; the recording then reaches the last sync before the cut.
  {
    std::vector<std::string> again = args;
    again.insert(again.end(), {"--duration", "1"});
    harness::ChildProcess daemon(test::binary("pandarcapd"), again, dir / "log-after.txt");
    const std::optional<int> status = daemon.wait_exit(60s);
    INFO(daemon.log());
    REQUIRE(status == 0);
  }
  const std::int64_t must_reach_ns =
      cut_ns - static_cast<std::int64_t>((kSyncIntervalSeconds + 1.5) * 1e9);
  // A disk whose syncs stalled (the daemon says so when its health file's takes 2 s: a loop
  // image on a busy machine, once in some 15 CI runs) held back the recordings' syncs too: what
  // the recording reaches is then the disk's, not the daemon's, and only its wholeness is
  // checked. Failed (2026-12-01): 0.77 s short of the bound after such a stall.
  const bool syncs_stalled =
      harness::read_file(dir / "log-cut.txt").find("no sync of the health file") !=
      std::string::npos;
  if (syncs_stalled)
    WARN("the disk's syncs stalled before the cut: how far the recording reaches is not checked");
  for (const fs::path& part : parts) {
    const fs::path recovered = part.string().substr(0, part.string().size() - 5);
    INFO(recovered.string());
    CHECK_FALSE(fs::exists(part));
    if (!fs::exists(recovered)) {
      // Removed as holding no whole record: only a cut before its first sync may leave that.
      CHECK(cut_after < std::chrono::duration<double>(kSyncIntervalSeconds + 1.5));
      continue;
    }
    std::uint64_t packets = 0;
    const std::int64_t last_ns = check_recording_whole(recovered, packets);
    if (!syncs_stalled) CHECK(last_ns >= must_reach_ns);
    if (std::string(mode.directory) == "raw") {
      const std::string stem =
          recovered.string().substr(0, recovered.string().size() - std::string(mode.suffix).size());
      CHECK(fs::file_size(stem + ".calibration.csv") > 0);
      CHECK(fs::file_size(stem + ".sensor.json") > 0);
    }
  }
  // The recording open at the cut had synced for longer than the bound: it is there.
  if (cut_after >= 4500ms) CHECK_FALSE(parts.empty());
  // Every recording has its sidecars; the health history reads line by line.
  for (const char* suffix : {".pcap", ".pcap.zst"}) {
    for (const fs::path& f : test::files_ending(out / "raw", suffix)) {
      const std::string stem = f.string().substr(0, f.string().size() - std::string(suffix).size());
      INFO(f.string());
      CHECK(fs::exists(stem + ".calibration.csv"));
      CHECK(fs::exists(stem + ".sensor.json"));
    }
  }
  CHECK_FALSE(test::health_records(out).empty());
}

void power_cut_trials(const Mode& mode, int trials) {
  std::random_device seed;
  const unsigned s = seed();
  INFO("seed " << s);
  std::mt19937 random(s);
  // From before the first sync (1 s) to well past the second.
  std::uniform_int_distribution<int> moment(1000, 7000);
  for (int i = 0; i < trials; ++i)
    power_cut_trial(mode, std::chrono::milliseconds(moment(random)));
}

const Mode kDefault{"default", {}, "raw", ".pcap"};
const Mode kZstd{"pcap-zst", {"--pcap-compression", "zstd"}, "raw", ".pcap.zst"};
const Mode kMcap{"mcap", {"--mcap", "--mcap-packets"}, "mcap", ".mcap"};
// XFS leaves what it had not written as zeros (a known trait after a crash), where ext4's
// ordered mode leaves nothing: the recovery must tell those from records.
const Mode kXfs{"default-xfs", {}, "raw", ".pcap", "xfs"};

// Fewer under the sanitizers, whose runs are slower: the moments are random in every run.
constexpr int kTrials = test::kSlowBuild ? 1 : 2;

}  // namespace

TEST_CASE("power cut: default outputs, cut at random moments", "[power][threads]") {
  power_cut_trials(kDefault, kTrials);
}

TEST_CASE("power cut: pcap.zst recordings, cut at random moments", "[power][threads]") {
  power_cut_trials(kZstd, kTrials);
}

TEST_CASE("power cut: MCAP with packets, cut at random moments", "[power][threads]") {
  power_cut_trials(kMcap, kTrials);
}

TEST_CASE("power cut: default outputs on XFS, cut at random moments", "[power][threads]") {
  power_cut_trials(kXfs, kTrials);
}

// The long variant: ctest --preset release -R power_cut_long (or the binary with
// "[.power-long]"): 10 cuts per output kind.
TEST_CASE("power cut, long: 10 random moments per output kind and on XFS",
          "[.power-long][threads]") {
  for (const Mode* mode : {&kDefault, &kZstd, &kMcap, &kXfs})
    power_cut_trials(*mode, 10);
}
