// The free-space floor (daemon/output/space_floor.hpp) and the hours left
// (core/health/storage_rate.hpp): which files are ours, the oldest removed first across outputs on
// a fake disk, other programs' files and the open recordings left alone, the counts; the write-rate
// window and hours_left arithmetic; the storage gauges in the JSON line and the .prom; the policy's
// min_hours_left. Then a real daemon on a small tmpfs with earlier runs' files and a foreign file.
#include <fmt/format.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <regex>
#include <set>
#include <string>
#include <vector>

#include "bench/child_process.hpp"
#include "core/health/health_format.hpp"
#include "core/health/health_policy.hpp"
#include "core/health/storage_rate.hpp"
#include "daemon/output/retention.hpp"
#include "daemon/output/space_floor.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
using namespace std::chrono_literals;
using nlohmann::json;
namespace fs = std::filesystem;

namespace {

constexpr std::uint64_t kFileBytes = 64 * 1024;

// A file of `bytes` real bytes (no holes: its blocks are its size) modified at `age_s` seconds
// after an arbitrary origin.
void make_file(const fs::path& path, int age_s, std::uint64_t bytes = kFileBytes) {
  std::ofstream(path, std::ios::binary) << std::string(bytes, 'x');
  const auto origin = fs::file_time_type::clock::now() - std::chrono::hours(24);
  fs::last_write_time(path, origin + std::chrono::seconds(age_s));
}

// A disk of `capacity` bytes holding everything under `root`: its free space is what the files
// there leave (their blocks).
struct FloorFakeDisk {
  fs::path root;
  std::uint64_t capacity;
  std::optional<FileSystemSpace> operator()(const fs::path&) const {
    std::uint64_t used = 0;
    for (const auto& entry : fs::recursive_directory_iterator(root)) {
      struct stat info {};
      if (::lstat(entry.path().c_str(), &info) == 0 && S_ISREG(info.st_mode))
        used += static_cast<std::uint64_t>(info.st_blocks) * 512;
    }
    return FileSystemSpace{capacity > used ? capacity - used : 0, capacity};
  }
};

// The blocks the files under `root` hold.
std::uint64_t used_blocks(const fs::path& root) {
  constexpr std::uint64_t kBig = 1ull << 50;
  return kBig - FloorFakeDisk{root, kBig}(root)->free;
}

// An output directory tree as earlier runs and other programs left it. Ours, oldest first:
//   raw pcap (100), mcap (200), frame (300), raw pcap.zst (400), frame (500)
// and, older than all of them, what is not ours to remove.
struct Tree {
  fs::path frames, raw, mcap;
  enum AsItIs { kAsItIs };
  // A tree already there (copied): only its paths.
  Tree(const fs::path& root, AsItIs)
      : frames(root / "frames"), raw(root / "raw"), mcap(root / "mcap") {}
  explicit Tree(const fs::path& root)
      : frames(root / "frames"), raw(root / "raw"), mcap(root / "mcap") {
    for (const fs::path& d : {frames, raw, mcap})
      fs::create_directories(d);
    make_file(raw / "pandarcap_20260101T000000Z_0000.pcap", 100);
    make_file(mcap / "pandarcap_20260101T000001Z_0000.mcap", 200);
    make_file(frames / "frame_000000_20260101T000002.000Z.pcd", 300);
    make_file(raw / "pandarcap_20260101T000003Z_0001.pcap.zst", 400);
    make_file(frames / "frame_000001_20260101T000004.000Z_partial.pcd", 500);
    // Not ours, all older: the open recordings, temporaries, the calibration, other programs'
    // files (one named almost like ours), a link and a directory with our names.
    make_file(raw / "pandarcap_20260101T000005Z_0002.pcap.part", 1);
    make_file(raw / "pandarcap_20260101T000006Z_0003.pcap.zst.part", 2);
    make_file(mcap / "pandarcap_20260101T000007Z_0001.mcap.part", 3);
    make_file(frames / ".frame_000002_20260101T000008.000Z.pcd.tmp", 4);
    make_file(raw / "calibration.csv", 5);
    make_file(raw / "notes.pcap", 6);
    make_file(raw / "pandarcap_backup.pcap", 7);
    make_file(mcap / "someone-elses.mcap", 8);
    make_file(frames / "frame_abc.pcd", 9);
    make_file(raw / "foreign-target.bin", 10);
    fs::create_symlink(raw / "foreign-target.bin", raw / "pandarcap_20250101T000000Z_0009.pcap");
    fs::create_directories(mcap / "pandarcap_20250101T000000Z_0008.mcap");
  }
  std::vector<fs::path> ours() const {
    return {raw / "pandarcap_20260101T000000Z_0000.pcap",
            mcap / "pandarcap_20260101T000001Z_0000.mcap",
            frames / "frame_000000_20260101T000002.000Z.pcd",
            raw / "pandarcap_20260101T000003Z_0001.pcap.zst",
            frames / "frame_000001_20260101T000004.000Z_partial.pcd"};
  }
  std::vector<fs::path> not_ours() const {
    return {raw / "pandarcap_20260101T000005Z_0002.pcap.part",
            raw / "pandarcap_20260101T000006Z_0003.pcap.zst.part",
            mcap / "pandarcap_20260101T000007Z_0001.mcap.part",
            frames / ".frame_000002_20260101T000008.000Z.pcd.tmp",
            raw / "calibration.csv",
            raw / "notes.pcap",
            raw / "pandarcap_backup.pcap",
            mcap / "someone-elses.mcap",
            frames / "frame_abc.pcd",
            raw / "foreign-target.bin",
            raw / "pandarcap_20250101T000000Z_0009.pcap",
            mcap / "pandarcap_20250101T000000Z_0008.mcap"};
  }
};

struct Removed {
  FloorKind kind;
  std::string path;
};

// The arguments of unshare running pandarcapd (with `daemon_args`) on a fresh tmpfs of `size` at
// `mount_point`, `seed` copied in first; at the end the health folder is copied out to
// MOUNT_POINT.after/ and the files left are listed in MOUNT_POINT.after/files (the mount goes
// with the namespace). As test::tmpfs_run_args, as root directly, otherwise in a user namespace;
// empty where neither can be had.
std::vector<std::string> seeded_tmpfs_args(const fs::path& mount_point, const fs::path& seed,
                                           const std::string& size,
                                           const std::vector<std::string>& daemon_args) {
  if (test::run_command("unshare " +
                        std::string(::geteuid() == 0 ? "" : "--user --map-root-user ") +
                        "--mount true 2>/dev/null")
          .exit_code != 0) {
    return {};
  }
  std::vector<std::string> args;
  if (::geteuid() != 0) args = {"--user", "--map-root-user"};
  for (const std::string& a :
       {std::string("--mount"), std::string("--propagation"), std::string("private"),
        std::string("--"), std::string("/bin/sh"), std::string("-c"),
        "mount -t tmpfs -o size=" + size +
            " pandarcap-test \"$0\" && cp -a \"$1\"/. \"$0\"/ "
            "&& shift && { \"$@\"; status=$?; mkdir -p \"$0.after\"; "
            "cp -r \"$0/health\" \"$0.after/\"; "
            "(cd \"$0\" && find . -type f) >\"$0.after/files\"; exit $status; }",
        mount_point.string(), seed.string(), test::binary("pandarcapd").string(),
        std::string("--allow-root")})
    args.push_back(a);
  args.insert(args.end(), daemon_args.begin(), daemon_args.end());
  return args;
}

// The files left on the tmpfs of a seeded_tmpfs_args run, relative to it.
std::set<std::string> files_left(const fs::path& mount_point) {
  std::set<std::string> left;
  std::ifstream in(fs::path(mount_point.string() + ".after") / "files");
  for (std::string line; std::getline(in, line);)
    left.insert(line.substr(2));  // without "./"
  return left;
}

}  // namespace

TEST_CASE("Space floor: which files are ours", "[output][space]") {
  CHECK(floor_file_is_ours(FloorKind::kFrames, "frame_000123_20261122T120000.123Z.pcd"));
  CHECK(floor_file_is_ours(FloorKind::kFrames, "frame_000123_20261122T120000.123Z_partial.pcd"));
  CHECK(floor_file_is_ours(FloorKind::kFrames, "frame_000123_20261122T120000.123Z_dup1.pcd"));
  CHECK(floor_file_is_ours(FloorKind::kRecordings, "pandarcap_20261122T120000Z_0007.pcap"));
  CHECK(floor_file_is_ours(FloorKind::kRecordings, "pandarcap_20261122T120000Z_0007.pcap.zst"));
  CHECK(floor_file_is_ours(FloorKind::kRecordings, "pandarcap_20261122T120000Z_0007_dup2.pcap"));
  CHECK(floor_file_is_ours(FloorKind::kMcap, "pandarcap_20261122T120000Z_0007.mcap"));
  for (const char* name :
       {"pandarcap_20261122T120000Z_0007.pcap.part",
        "pandarcap_20261122T120000Z_0007.pcap.zst.part",
        ".pandarcap_20261122T120000Z_0007.pcap.tmp", "pandarcap_20261122T120000Z_.pcap",
        "pandarcap_20261122T120000Z_0007x.pcap", "pandarcap_backup.pcap", "calibration.csv",
        "sensor.json", "calibration_before_0003.csv", "notes.pcap", ".pcap", "pandarcap_.pcap",
        "pandarcap_20261122T120000Z_0007.mcap"}) {
    INFO(name);
    CHECK_FALSE(floor_file_is_ours(FloorKind::kRecordings, name));
  }
  CHECK_FALSE(floor_file_is_ours(FloorKind::kMcap, "pandarcap_20261122T120000Z_0007.mcap.part"));
  CHECK_FALSE(floor_file_is_ours(FloorKind::kMcap, "pandarcap_20261122T120000Z_0007.pcap"));
  CHECK_FALSE(floor_file_is_ours(FloorKind::kFrames, "frame_abc.pcd"));
  CHECK_FALSE(floor_file_is_ours(FloorKind::kFrames, ".frame_000001_x.pcd.tmp"));
  CHECK_FALSE(floor_file_is_ours(FloorKind::kFrames, "frame_000001_x.pcd.tmp"));
  CHECK_FALSE(floor_file_is_ours(FloorKind::kNone, "frame_000001_x.pcd"));
}

TEST_CASE("Space floor: the oldest of ours go first, across outputs, and nothing else is touched",
          "[output][space]") {
  test::ScratchDir dir("space-floor");
  const Tree tree(dir.path());
  const std::uint64_t used = used_blocks(dir.path());
  // The disk is 4 MiB; the floor asks for what it has free now plus 2.5 files: three must go.
  const FloorFakeDisk disk{dir.path(), used + 4 * 1024 * 1024};
  const std::uint64_t floor = 4 * 1024 * 1024 + 5 * kFileBytes / 2;
  SpaceFloor space(floor, 0, 0);  // the configured floor alone (a 4 MiB disk)
  space.ask_space_with(disk);
  std::vector<Removed> removed;
  space.on_removed([&](FloorKind kind, std::string_view path, std::uint64_t) {
    removed.push_back({kind, std::string(path)});
  });
  const int frames = space.watch(tree.frames, FloorKind::kFrames);
  space.watch(tree.raw, FloorKind::kRecordings);
  space.watch(tree.mcap, FloorKind::kMcap);
  space.prepare();
  REQUIRE(space.enabled());
  CHECK(space.file_system(frames) == 0);  // one file system: one volume

  space.tend(1'000'000'000);
  const std::vector<fs::path> ours = tree.ours();
  REQUIRE(removed.size() == 3);
  CHECK(removed[0].path == ours[0].native());
  CHECK(removed[0].kind == FloorKind::kRecordings);
  CHECK(removed[1].path == ours[1].native());
  CHECK(removed[1].kind == FloorKind::kMcap);
  CHECK(removed[2].path == ours[2].native());
  CHECK(removed[2].kind == FloorKind::kFrames);
  for (std::size_t i = 0; i < ours.size(); ++i) {
    INFO(ours[i]);
    CHECK(fs::exists(ours[i]) == (i >= 3));
  }
  for (const fs::path& p : tree.not_ours()) {
    INFO(p);
    CHECK(fs::exists(fs::symlink_status(p)));
  }
  CHECK(space.files_removed() == 3);
  CHECK(space.bytes_removed() == 3 * kFileBytes);
  REQUIRE(space.free_bytes(frames).has_value());
  CHECK(*space.free_bytes(frames) >= floor);

  // Above the floor again: nothing more goes.
  space.tend(2'000'000'000);
  CHECK(space.files_removed() == 3);

  // Someone else fills the disk: the rest of ours goes (the newest last), and nothing else;
  // the floor cannot be held, which is said, not fought.
  make_file(dir / "someone-elses-big-file", 1000, 4 * 1024 * 1024);
  space.tend(3'000'000'000);
  CHECK(space.files_removed() == 5);
  CHECK(space.bytes_removed() == 5 * kFileBytes);
  for (const fs::path& p : ours)
    CHECK_FALSE(fs::exists(p));
  for (const fs::path& p : tree.not_ours()) {
    INFO(p);
    CHECK(fs::exists(fs::symlink_status(p)));
  }
  CHECK(fs::exists(dir / "someone-elses-big-file"));
  space.tend(4'000'000'000);  // nothing left to remove: no error, no loop
  CHECK(space.files_removed() == 5);
}

TEST_CASE("Space floor: min_free_percent, and no floor at all", "[output][space]") {
  test::ScratchDir dir("space-floor-percent");
  const Tree tree(dir.path());
  const std::uint64_t used = used_blocks(dir.path());
  // A percentage of the disk's size 1.5 files above its free space: two files go.
  const FloorFakeDisk disk{dir.path(), used + 10 * kFileBytes - 3 * kFileBytes / 2};
  {
    SpaceFloor space(0, 100.0 * 10 * kFileBytes / static_cast<double>(disk.capacity), 0);
    space.ask_space_with(disk);
    space.watch(tree.frames, FloorKind::kFrames);
    space.watch(tree.raw, FloorKind::kRecordings);
    space.watch(tree.mcap, FloorKind::kMcap);
    space.prepare();
    space.tend(1'000'000'000);
    CHECK(space.files_removed() == 2);
    CHECK_FALSE(fs::exists(tree.ours()[0]));
    CHECK_FALSE(fs::exists(tree.ours()[1]));
    CHECK(fs::exists(tree.ours()[2]));
  }
  {
    // No floor (and no reserve under it): the free space is reported, nothing is removed.
    SpaceFloor space(0, 0, 0);
    space.ask_space_with(FloorFakeDisk{dir.path(), used});
    const int raw = space.watch(tree.raw, FloorKind::kRecordings);
    space.prepare();
    CHECK_FALSE(space.enabled());
    space.tend(1'000'000'000);
    CHECK(space.files_removed() == 0);
    REQUIRE(space.free_bytes(raw).has_value());
    CHECK(fs::exists(tree.ours()[2]));
  }
}

TEST_CASE("Space floor: the real file system's free space is asked", "[output][space]") {
  test::ScratchDir dir("space-floor-statvfs");
  SpaceFloor space(0, 0, 0);
  const int here = space.watch(dir.path(), FloorKind::kNone);
  const int gone = space.watch(dir / "not-yet" / "deeper", FloorKind::kNone);
  space.prepare();
  space.tend(1);
  REQUIRE(space.free_bytes(here).has_value());
  CHECK(*space.free_bytes(here) > 0);
  REQUIRE(space.free_bytes(gone).has_value());  // asked at its nearest existing parent
  const auto asked = file_system_space_at(dir.path());
  REQUIRE(asked.has_value());
  CHECK(asked->size >= asked->free);
}

TEST_CASE("Space floor: a file removed on purpose is not counted as lost", "[output][space]") {
  test::ScratchDir dir("space-floor-recorded");
  const Retention retention(0, 0);
  RecordedFiles recorded;
  const std::string a = (dir / "pandarcap_20260101T000000Z_0000.pcap").native();
  const std::string b = (dir / "pandarcap_20260101T000001Z_0001.pcap").native();
  const std::string c = (dir / "pandarcap_20260101T000002Z_0002.pcap").native();
  for (const std::string& p : {a, b, c}) {
    make_file(p, 0);
    recorded.add(p, 100, retention);
  }
  // The floor removes a; someone else removes b.
  fs::remove(a);
  recorded.forget(a);
  fs::remove(b);
  const RecordedFiles::Gone gone = recorded.take_gone();
  CHECK(gone.files == 1);
  CHECK(gone.items == 100);

  Retention limited(2, 0);
  limited.adopt(a, 10);
  limited.adopt(b, 10);
  limited.forget(a);  // gone with the floor: off the list, so the limit is not reached
  CHECK(limited.size() == 1);
  CHECK(limited.enforce() == 0);
}

TEST_CASE("Hours left: the write rate over the last minute", "[health][space]") {
  WriteRateWindow w;
  constexpr std::int64_t s = 1'000'000'000;
  CHECK(w.rate(0) == 0);
  w.sample(0, {0, 0, 0, 0});
  CHECK(w.rate(0) == 0);  // one sample: no rate yet
  // 1 MB/s of frames and 0.5 MB/s of pcap for 10 s.
  for (std::int64_t t = 1; t <= 10; ++t)
    w.sample(t * s, {static_cast<std::uint64_t>(t) * 1'000'000,
                     static_cast<std::uint64_t>(t) * 500'000, 0, static_cast<std::uint64_t>(t)});
  CHECK(w.span_seconds() == Approx(10));
  CHECK(w.rate(0) == Approx(1e6));
  CHECK(w.rate(1) == Approx(5e5));
  CHECK(w.rate(2) == 0);
  CHECK(w.rate(3) == Approx(1));
  // An early health record (packets stopped) half a second later is not a sample.
  w.sample(10 * s + s / 2, {99'000'000'000, 0, 0, 0});
  CHECK(w.rate(0) == Approx(1e6));
  // Frames stop for two minutes: the rate falls to 0 once the minute has passed.
  for (std::int64_t t = 11; t <= 130; ++t)
    w.sample(t * s, {10'000'000, static_cast<std::uint64_t>(t) * 500'000, 0, 0});
  CHECK(w.span_seconds() == Approx(60));
  CHECK(w.rate(0) == 0);
  CHECK(w.rate(1) == Approx(5e5));
  CHECK(w.rate(3) == 0);  // health stopped too
  // A counter taken back (a failed pcap batch's records) reads as nothing written.
  WriteRateWindow back;
  back.sample(0, {100, 0, 0, 0});
  back.sample(s, {50, 0, 0, 0});
  CHECK(back.rate(0) == 0);

  CHECK(hours_left(3'600'000'000, 1e6) == Approx(1.0));
  CHECK(std::isinf(hours_left(1'000, 0)));

  // Two file systems: frames and health on one (id 0), pcap on another (id 1) that fills first.
  StorageInputs in;
  in.free_bytes = {std::uint64_t{1'000'000'000'000}, std::uint64_t{1'800'000'000}, std::nullopt,
                   std::uint64_t{1'000'000'000'000}};
  in.file_system = {0, 1, -1, 0};
  StorageGauges st;
  fill_storage(w, in, st);
  CHECK(st.free_known);
  CHECK(st.free_bytes == 1'800'000'000);
  CHECK(st.hours_left == Approx(1.0));  // 1.8 GB at 0.5 MB/s
  CHECK(st.written_bytes_per_second_total == Approx(5e5));
  // Nothing written: hours are infinite, and the least free space is reported.
  fill_storage(WriteRateWindow{}, in, st);
  CHECK(std::isinf(st.hours_left));
  CHECK(st.free_bytes == 1'800'000'000);
  // Nothing asked: unknown.
  fill_storage(w, StorageInputs{}, st);
  CHECK_FALSE(st.free_known);
}

TEST_CASE("Hours left: below health.min_hours_left is degraded, with the reason",
          "[health][policy][space]") {
  HealthCounters c;
  HealthGauges g;
  g.return_mode = "last";
  g.rpm_tail = 600;
  g.seconds_since_last_packet = 0.01;
  g.storage.free_known = true;
  g.storage.free_bytes = 3ull << 30;
  g.storage.written_bytes_per_second_total = 1.1e6;
  g.storage.hours_left = 0.8;
  classify_health(c, c, HealthExpectations{"last", 600, 0, 1.0}, false, "", g);
  CHECK(g.state == HealthState::kDegraded);
  CHECK(g.reason ==
        "0.8 hours of disk left (3072 MiB free at 1.1 MB/s written; health.min_hours_left 1)");
  // Enough hours, nothing written (infinite), not checked, or not known: ok.
  g.storage.hours_left = 1.5;
  classify_health(c, c, HealthExpectations{"last", 600, 0, 1.0}, false, "", g);
  CHECK(g.state == HealthState::kOk);
  g.storage.hours_left = std::numeric_limits<double>::infinity();
  classify_health(c, c, HealthExpectations{"last", 600, 0, 1.0}, false, "", g);
  CHECK(g.state == HealthState::kOk);
  g.storage.hours_left = 0.1;
  classify_health(c, c, HealthExpectations{"last", 600, 0, 0}, false, "", g);
  CHECK(g.state == HealthState::kOk);
  g.storage.free_known = false;
  classify_health(c, c, HealthExpectations{"last", 600, 0, 1.0}, false, "", g);
  CHECK(g.state == HealthState::kOk);
}

TEST_CASE("Hours left: the storage gauges in the JSON line and the .prom", "[health][format]") {
  HealthSnapshot h;
  h.sensor = "front";
  h.counters.files_removed_for_space = 7;
  h.counters.bytes_removed_for_space = 7000;
  StorageGauges& st = h.gauges.storage;
  st.free_known = true;
  st.free_bytes = 7'200'000'000;
  st.written_bytes_per_second = {1e6, 5e5, 0, 100};
  st.written_bytes_per_second_total = 1.5001e6;
  st.hours_left = 2.5;
  json j = json::parse(to_json_line(h));
  CHECK(j.at("counters").at("files_removed_for_space") == 7);
  CHECK(j.at("counters").at("bytes_removed_for_space") == 7000);
  const json& s = j.at("storage");
  CHECK(s.at("free_bytes") == 7'200'000'000);
  CHECK(s.at("hours_left") == 2.5);
  CHECK(s.at("written_bytes_per_second").at("frames") == 1e6);
  CHECK(s.at("written_bytes_per_second").at("pcap") == 5e5);
  CHECK(s.at("written_bytes_per_second").at("mcap") == 0);
  CHECK(s.at("written_bytes_per_second").at("health") == 100);
  CHECK(s.at("written_bytes_per_second").at("total") == 1.5001e6);
  auto prom = test::prom_samples(to_prometheus(h));
  CHECK(prom.at("pandarcap_files_removed_for_space_total{sensor=\"front\"}") == "7");
  CHECK(prom.at("pandarcap_removed_for_space_bytes_total{sensor=\"front\"}") == "7000");
  CHECK(prom.at("pandarcap_storage_free_bytes{sensor=\"front\"}") == "7200000000");
  CHECK(prom.at("pandarcap_storage_time_left_seconds{sensor=\"front\"}") == "9000");  // 2.5 h
  CHECK(prom.at("pandarcap_storage_written_bytes_per_second{sensor=\"front\",output=\"pcap\"}") ==
        "500000");
  CHECK(prom.count(
            "pandarcap_storage_written_bytes_per_second{sensor=\"front\",output=\"health\"}") == 1);

  // Nothing written: JSON null, the .prom +Inf (an alert on "< 1" stays silent).
  st.hours_left = std::numeric_limits<double>::infinity();
  j = json::parse(to_json_line(h));
  CHECK(j.at("storage").at("hours_left").is_null());
  prom = test::prom_samples(to_prometheus(h));
  CHECK(prom.at("pandarcap_storage_time_left_seconds{sensor=\"front\"}") == "+Inf");
  if (test::run_command("command -v promtool >/dev/null").exit_code == 0) {
    test::ScratchDir dir("storage-prom");
    std::ofstream(dir / "pandarcap.prom") << to_prometheus(h);
    std::string said;
    const bool accepted = test::promtool_accepts(dir / "pandarcap.prom", said);
    INFO(said);
    CHECK(accepted);  // +Inf is a valid sample
  }
  // The free space unknown: null, and neither sample.
  st.free_known = false;
  j = json::parse(to_json_line(h));
  CHECK(j.at("storage").at("free_bytes").is_null());
  CHECK(j.at("storage").at("hours_left").is_null());
  prom = test::prom_samples(to_prometheus(h));
  CHECK(prom.count("pandarcap_storage_time_left_seconds{sensor=\"front\"}") == 0);
  CHECK(prom.count("pandarcap_storage_free_bytes{sensor=\"front\"}") == 0);
}

TEST_CASE("Space floor: a daemon on a small disk with earlier runs' files and a foreign one",
          "[daemon][space][disk][threads]") {
  test::ScratchDir dir("space-floor-daemon");
  // What earlier runs and another program left, copied onto a fresh 160 MiB tmpfs before the
  // daemon starts: three of our files (8 MiB each, a day old) and another program's (4 MiB, older
  // still), one named like an open recording.
  const fs::path seed = dir / "seed";
  for (const char* d : {"frames", "raw", "mcap"})
    fs::create_directories(seed / d);
  const std::vector<std::string> earlier = {"raw/pandarcap_20250101T000000Z_0000.pcap",
                                            "mcap/pandarcap_20250101T000001Z_0000.mcap",
                                            "frames/frame_000000_20250101T000002.000Z.pcd"};
  for (std::size_t i = 0; i < earlier.size(); ++i)
    make_file(seed / earlier[i], 100 + static_cast<int>(i), 8 << 20);
  const std::vector<std::string> foreign = {"raw/someone-elses-capture.pcap", "frames/notes.txt"};
  make_file(seed / foreign[0], 1, 4 << 20);
  make_file(seed / foreign[1], 2, 1000);
  // The floor 64 MiB above the 32 MiB the health files keep: the ~2 s of writing (frames, pcap
  // and MCAP: ~35 MB/s) between two of the writer's once-a-second checks, with room to spare on
  // a busy machine, so that no write is ever refused. (At 32 MiB above, one late check was seen
  // to let a write reach the reserve.)
  const fs::path config = dir / "floor.toml";
  std::ofstream(config) << "[output]\nmcap = true\npcap_rotate_seconds = 1\nmcap_rotate_seconds = "
                           "1\nmin_free_bytes = 100663296\n";
  const fs::path mount_point = dir / "out";
  fs::create_directories(mount_point);
  const std::vector<std::string> args =
      seeded_tmpfs_args(mount_point, seed, "160m",
                        {"-c", config.string(), "--simulate", "--duration", "8", "--output-dir",
                         mount_point.string()});
  if (args.empty()) {
    WARN("cannot create a mount namespace here (no root, no user namespaces): not tested");
    return;
  }
  harness::ChildProcess daemon("/usr/bin/unshare", args, dir / "log.txt");
  REQUIRE(daemon.wait_exit(60s) == 0);
  const std::string log = daemon.log();
  INFO(log);

  const std::set<std::string> left = files_left(mount_point);
  REQUIRE_FALSE(left.empty());
  // The floor was reached: the earlier runs' files went first, the foreign ones stayed.
  for (const std::string& f : earlier) {
    INFO(f);
    CHECK(left.count(f) == 0);
  }
  for (const std::string& f : foreign) {
    INFO(f);
    CHECK(left.count(f) == 1);
  }
  CHECK(log.find("of our oldest files removed") != std::string::npos);

  const fs::path health = fs::path(mount_point.string() + ".after") / "health";
  const auto records = test::json_lines(health / "health.jsonl");
  REQUIRE_FALSE(records.empty());
  const json& last = records.back();
  INFO(last.dump());
  const std::uint64_t removed = test::health_counter(last, "files_removed_for_space");
  CHECK(removed > earlier.size());  // and this run's oldest after them
  CHECK(test::health_counter(last, "bytes_removed_for_space") > (24u << 20));
  // The disk never filled: no write refused or failed.
  CHECK(test::health_counter(last, "write_errors") == 0);
  // Removed on purpose, not lost: the recorded counts stay what was recorded.
  CHECK(test::health_counter(last, "pcap_packets_lost") == 0);
  CHECK(test::health_counter(last, "mcap_messages_lost") == 0);
  CHECK(log.find("more lost with their file") == std::string::npos);  // the MCAP summary line
  CHECK(last.at("storage").at("free_bytes").get<std::uint64_t>() > 0);
  CHECK(last.at("storage").at("written_bytes_per_second").at("total").get<double>() > 1e6);
  CHECK(last.at("storage").at("hours_left").get<double>() > 0);
  const auto prom = test::prom_samples(harness::read_file(health / "pandarcap.prom"));
  CHECK(prom.at("pandarcap_files_removed_for_space_total{sensor=\"pandar40p\"}") ==
        std::to_string(removed));
  CHECK(prom.count("pandarcap_storage_time_left_seconds{sensor=\"pandar40p\"}") == 1);
  CHECK(log.find(fmt::format("free-space floor: {} of the oldest files", removed)) !=
        std::string::npos);
  std::smatch m;
  REQUIRE(std::regex_search(log, m, std::regex(R"(([0-9]+) packets recorded)")));
  CHECK(std::stoull(m[1].str()) == test::health_counter(last, "pcap_packets_written"));
}

TEST_CASE("Space floor: never below the health files' room plus 2 s of writing",
          "[output][space]") {
  test::ScratchDir dir("space-floor-minimum");
  const Tree tree(dir.path());
  const std::uint64_t used = used_blocks(dir.path());
  // The guard's room here is 1 MiB (the daemon's is 32 MiB); the disk has 1 MiB + 1.5 files
  // free, and the configured floors are all below what the room needs.
  constexpr std::uint64_t kRoom = 1 << 20;
  for (const std::uint64_t configured : {std::uint64_t{0}, std::uint64_t{1000}, kRoom / 2}) {
    INFO("min_free_bytes " << configured);
    test::ScratchDir copy("space-floor-minimum-run");
    fs::copy(dir.path(), copy.path(),
             fs::copy_options::recursive | fs::copy_options::copy_symlinks);
    const Tree moved{copy.path(), Tree::kAsItIs};
    const FloorFakeDisk disk{copy.path(), used + kRoom + 3 * kFileBytes / 2};
    SpaceFloor space(configured, 0, kRoom);
    space.ask_space_with(disk);
    const int frames = space.watch(moved.frames, FloorKind::kFrames);
    space.watch(moved.raw, FloorKind::kRecordings);
    space.watch(moved.mcap, FloorKind::kMcap);
    space.prepare();
    REQUIRE(space.enabled());
    // Nothing written yet: the room alone, which the disk has.
    space.tend(1'000'000'000);
    CHECK(space.files_removed() == 0);
    CHECK(space.floor_bytes(frames) == kRoom);
    // 1.5 files a second measured: 3 files' worth more (2 s), so two files go (1.5 free above).
    space.write_rate(1.5 * kFileBytes, 2'000'000'000);
    CHECK(space.minimum_bytes() == kRoom + 3 * kFileBytes);
    space.tend(2'000'000'000);
    CHECK(space.files_removed() == 2);
    CHECK(*space.free_bytes(frames) >= kRoom + 3 * kFileBytes);
    // A slower rate does not lower it again.
    space.write_rate(0, 3'000'000'000);
    CHECK(space.minimum_bytes() == kRoom + 3 * kFileBytes);
    CHECK(space.floor_bytes(frames) == kRoom + 3 * kFileBytes);
  }
  // A configured floor above the minimum stays what it is.
  SpaceFloor high(64 << 20, 0, kRoom);
  high.ask_space_with(FloorFakeDisk{dir.path(), used + (128 << 20)});
  const int raw = high.watch(tree.raw, FloorKind::kRecordings);
  high.prepare();
  high.write_rate(kFileBytes, 1);
  high.tend(1);
  CHECK(high.floor_bytes(raw) == (64u << 20));
  CHECK(high.files_removed() == 0);
}

TEST_CASE("Space floor: a write the guard would refuse makes room first, sidecars go along",
          "[output][space]") {
  test::ScratchDir dir("space-floor-make-room");
  const Tree tree(dir.path());
  // Sidecars of the oldest recording, and of one that is not removed.
  const fs::path sidecar_a = tree.raw / "pandarcap_20260101T000000Z_0000.calibration.csv";
  const fs::path sidecar_b = tree.raw / "pandarcap_20260101T000000Z_0000.sensor.json";
  const fs::path sidecar_kept = tree.raw / "pandarcap_20260101T000003Z_0001.sensor.json";
  for (const fs::path& p : {sidecar_a, sidecar_b, sidecar_kept})
    make_file(p, 2000, 100);  // newer than everything: they go with their recording, not alone
  const std::uint64_t used = used_blocks(dir.path());
  constexpr std::uint64_t kRoom = 1 << 20;
  // Just the room free: the floor holds (nothing written yet), but a write of one file does not
  // fit above the room.
  const FloorFakeDisk disk{dir.path(), used + kRoom};
  SpaceFloor space(0, 0, kRoom);
  space.ask_space_with(disk);
  std::vector<Removed> removed;
  space.on_removed([&](FloorKind kind, std::string_view path, std::uint64_t bytes) {
    removed.push_back({kind, std::string(path)});
    CHECK(bytes == kFileBytes);
  });
  space.watch(tree.frames, FloorKind::kFrames);
  space.watch(tree.raw, FloorKind::kRecordings);
  space.watch(tree.mcap, FloorKind::kMcap);
  space.prepare();
  space.tend(1'000'000'000);
  CHECK(space.files_removed() == 0);

  // A directory that is not watched, or no room needed: nothing.
  CHECK_FALSE(space.make_room((dir / "elsewhere").native(), kFileBytes, 2));
  // The write of one file: the oldest of ours (the recording, with its sidecars) makes room.
  CHECK(space.make_room(tree.raw.native(), kFileBytes, 2));
  REQUIRE(removed.size() == 1);
  CHECK(removed[0].path == tree.ours()[0].native());
  CHECK_FALSE(fs::exists(sidecar_a));
  CHECK_FALSE(fs::exists(sidecar_b));
  CHECK(fs::exists(sidecar_kept));
  CHECK(disk(dir.path())->free >= kRoom + kFileBytes);
  // Three files more than there is: everything of ours goes, nothing else, and it says so.
  CHECK(space.make_room(tree.frames.native(), 8 * kFileBytes, 3));
  CHECK(space.files_removed() == 5);
  for (const fs::path& p : tree.not_ours()) {
    INFO(p);
    CHECK(fs::exists(fs::symlink_status(p)));
  }
  CHECK_FALSE(space.make_room(tree.frames.native(), 8 * kFileBytes, 4));

  // Retention takes a recording's sidecars along too, and says what it removed.
  const fs::path recording = tree.raw / "pandarcap_20260101T000009Z_0009.pcap.zst";
  const fs::path sidecar = tree.raw / "pandarcap_20260101T000009Z_0009.calibration.csv";
  make_file(recording, 10);
  make_file(sidecar, 10, 100);
  Retention retention(1, 0);
  std::vector<std::string> retired;
  retention.on_removed([&](std::string_view path, std::uint64_t bytes) {
    retired.emplace_back(path);
    CHECK(bytes == 7);
  });
  retention.adopt(recording.native(), 7);
  retention.add((tree.raw / "pandarcap_20260101T000010Z_0010.pcap").native(), 7);
  REQUIRE(retired.size() == 1);
  CHECK(retired[0] == recording.native());
  CHECK_FALSE(fs::exists(recording));
  CHECK_FALSE(fs::exists(sidecar));
}

TEST_CASE("Space floor: whatever the floor, earlier files of ours on a small disk, no write error",
          "[daemon][space][disk][threads]") {
  // Seven daemons at once, one per floor, each on its own 128 MiB tmpfs holding five earlier
  // recordings of ours (80 MB, a year old: 48 MB free at the start, the 40 MiB the start needs
  // and little more). Each writes frames and recordings (~25 MB/s) for 3 s. A floor below the
  // 32 MiB the health files keep plus 2 s of writing (all but the largest here) is raised to
  // that, and a write the guard would refuse makes room first: not one write is refused, and the
  // earlier recordings go. (A floor of 12 MB used to give 115 write errors in 15 s on a 256 MB
  // disk, with our older files still there.)
  test::ScratchDir dir("space-floor-matrix");
  const fs::path seed = dir / "seed";
  fs::create_directories(seed / "raw");
  std::vector<std::string> earlier;
  for (int i = 0; i < 5; ++i) {
    earlier.push_back(fmt::format("raw/pandarcap_20250101T00000{}Z_000{}.pcap", i, i));
    make_file(seed / earlier.back(), -365 * 24 * 3600 + i, 16'000'000);
  }
  // (A floor of 0 is none: nothing of ours is removed, as before; not this test's question.)
  std::vector<std::string> floors = {"min_free_bytes = 1",        "min_free_bytes = 1000000",
                                     "min_free_bytes = 12000000", "min_free_bytes = 40000000",
                                     "min_free_percent = 1",      "min_free_percent = 10",
                                     "min_free_percent = 30"};
  // Under ThreadSanitizer seven daemons at once would cost its job more than they tell it (the
  // release and ASan jobs run all seven): one of each form.
  if (test::kThreadSanitizerBuild)
    floors = {"min_free_bytes = 1", "min_free_bytes = 12000000", "min_free_percent = 10"};
  struct Run {
    std::string floor;
    fs::path mount_point;
    std::unique_ptr<harness::ChildProcess> daemon;
  };
  std::vector<Run> runs;
  for (std::size_t i = 0; i < floors.size(); ++i) {
    const fs::path config = dir / fmt::format("floor{}.toml", i);
    std::ofstream(config) << "[output]\npcap_rotate_seconds = 1\n" << floors[i] << "\n";
    const fs::path mount_point = dir / fmt::format("out{}", i);
    fs::create_directories(mount_point);
    const std::vector<std::string> args =
        seeded_tmpfs_args(mount_point, seed, "128m",
                          {"-c", config.string(), "--simulate", "--duration", "3", "--output-dir",
                           mount_point.string()});
    if (args.empty()) {
      WARN("cannot create a mount namespace here (no root, no user namespaces): not tested");
      return;
    }
    runs.push_back({floors[i], mount_point,
                    std::make_unique<harness::ChildProcess>("/usr/bin/unshare", args,
                                                            dir / fmt::format("log{}.txt", i))});
  }
  for (Run& run : runs) {
    INFO(run.floor);
    REQUIRE(run.daemon->wait_exit(120s) == 0);
    const std::string log = run.daemon->log();
    INFO(log);
    CHECK(log.find("; 0 write errors") != std::string::npos);  // the exit summary
    const auto records =
        test::json_lines(fs::path(run.mount_point.string() + ".after") / "health" / "health.jsonl");
    REQUIRE_FALSE(records.empty());
    INFO(records.back().dump());
    CHECK(test::health_counter(records.back(), "write_errors") == 0);
    CHECK(test::health_counter(records.back(), "bytes_not_written") == 0);
    // The floor made the room: the earlier recordings went, oldest first (all five at full
    // speed; a sanitizer build writes less in its 3 s and may need fewer).
    const std::set<std::string> left = files_left(run.mount_point);
    std::size_t gone = 0;
    while (gone < earlier.size() && left.count(earlier[gone]) == 0)
      ++gone;
    for (std::size_t i = gone; i < earlier.size(); ++i) {
      INFO(earlier[i] << " is left, and so must every newer one be");
      CHECK(left.count(earlier[i]) == 1);
    }
    CHECK(gone >= (test::kSlowBuild ? 1 : earlier.size()));
    CHECK(test::health_counter(records.back(), "files_removed_for_space") >= gone);
    // Below the health files' room plus 2 s of writing (at the start, or once the rate is
    // measured: every floor here), the log says it is raised.
    CHECK((log.find("the floor is raised to that") != std::string::npos ||
           log.find("free-space floor: raised to") != std::string::npos));
  }
}
