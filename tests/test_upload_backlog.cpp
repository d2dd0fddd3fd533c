// How far the upload is behind (daemon/output/upload_backlog.hpp): which files leave by upload,
// the backlog's figures over a directory with everything a vehicle may hold (and a pass read a
// little at a time), a directory that vanishes, a clock set back, the files removed before they
// were uploaded; the reason that names them; the JSON line's storage.upload and the .prom's
// gauges. The upload itself (rclone, the unit): tests/check_upload_unit.sh.
#include <fcntl.h>
#include <sys/stat.h>

#include <catch2/catch.hpp>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "core/health/health_format.hpp"
#include "core/health/health_policy.hpp"
#include "daemon/output/upload_backlog.hpp"
#include "daemon/pcap/recording_sidecars.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

constexpr std::int64_t kNs = 1'000'000'000;

// `bytes` bytes, finished at `mtime_s` seconds after the epoch.
void make_backlog_file(const fs::path& path, std::uint64_t bytes, std::int64_t mtime_s) {
  std::ofstream(path, std::ios::binary) << std::string(bytes, 'x');
  const timespec times[2] = {{mtime_s, 0}, {mtime_s, 0}};
  REQUIRE(::utimensat(AT_FDCWD, path.c_str(), times, 0) == 0);
}

}  // namespace

TEST_CASE("Upload: which files leave by upload, as the unit's rclone filter has them",
          "[output][upload]") {
  // The list the unit's own test moves with rclone (tests/check_upload_unit.sh).
  std::ifstream list(fs::path(PANDARCAP_SOURCE_DIR) / "tests" / "upload" / "names.txt");
  REQUIRE(list);
  int up = 0, stays = 0;
  for (std::string line; std::getline(list, line);) {
    if (line.empty() || line.front() == '#') continue;
    const std::size_t space = line.find(' ');
    REQUIRE(space != std::string::npos);
    const std::string verdict = line.substr(0, space), path = line.substr(space + 1);
    const std::string directory = path.substr(0, path.find('/'));
    const std::string name = path.substr(path.rfind('/') + 1);
    INFO(path);
    REQUIRE((verdict == "up" || verdict == "stays"));
    // frames/ is not an upload directory in that list, nor anything outside raw/ and mcap/.
    const bool uploaded_directory = directory == "raw" || directory == "mcap";
    CHECK((uploaded_directory && upload_file_is_ours(name)) == (verdict == "up"));
    (verdict == "up" ? up : stays)++;
  }
  CHECK(up >= 8);
  CHECK(stays >= 15);
  // Every file of ours the floor may remove is one that leaves by upload.
  for (const char* name :
       {"pandarcap_20261127T220805Z_0003.pcap", "pandarcap_20261127T220805Z_0003.pcap.zst",
        "pandarcap_20261127T220805Z_0003_dup1.mcap", "frame_000001_20261127T220805.000Z.pcd",
        "frame_000001_20261127T220805.000Z_partial.pcd"}) {
    INFO(name);
    CHECK(upload_file_is_ours(name));
  }
  CHECK(recording_stem("pandarcap_20261127T220805Z_0003.pcap.zst") ==
        "pandarcap_20261127T220805Z_0003");
  CHECK(recording_stem("pandarcap_20261127T220805Z_0003_dup2.pcap") ==
        "pandarcap_20261127T220805Z_0003_dup2");
  CHECK_FALSE(recording_stem("pandarcap_20261127T220805Z_0003.mcap"));
}

TEST_CASE("Upload: the backlog over the upload directories, read a little at a time",
          "[output][upload]") {
  test::ScratchDir dir("upload-backlog");
  const fs::path raw = dir / "raw", mcap = dir / "mcap", frames = dir / "frames";
  for (const fs::path& d : {raw, mcap, frames})
    fs::create_directories(d);
  // 150 recordings with their two sidecars, the oldest finished at t = 1000 s.
  std::uint64_t bytes = 0, files = 0;
  for (int i = 0; i < 150; ++i) {
    const std::string stem = "pandarcap_20261127T220805Z_" + std::to_string(1000 + i);
    make_backlog_file(raw / (stem + ".pcap.zst"), 100 + i, 1000 + i);
    make_backlog_file(raw / (stem + ".calibration.csv"), 10, 1000 + i);
    make_backlog_file(raw / (stem + ".sensor.json"), 20, 1000 + i);
    bytes += 100 + i + 30;
    files += 3;
  }
  make_backlog_file(mcap / "pandarcap_20261127T220805Z_0000.mcap", 5000, 3000);
  bytes += 5000;
  files += 1;
  // Not waiting for upload: the open files, temporaries, hidden files, raw/'s own calibration
  // and sensor.json, another program's files, a link and a directory named like ours; and
  // frames/, which is not an upload directory here (tests/upload/names.txt has more names).
  make_backlog_file(raw / "pandarcap_20261127T220805Z_2000.pcap.zst.part", 7000, 10);
  make_backlog_file(mcap / "pandarcap_20261127T220805Z_0001.mcap.part", 7000, 10);
  make_backlog_file(raw / ".pandarcap_20261127T220805Z_2001.sensor.json.tmp", 7000, 10);
  make_backlog_file(raw / ".hidden", 7000, 10);
  make_backlog_file(raw / "calibration.csv", 7000, 10);
  make_backlog_file(raw / "sensor.json", 7000, 10);
  make_backlog_file(raw / "notes.txt", 7000, 10);
  fs::create_symlink(raw / "notes.txt", raw / "pandarcap_20261127T220805Z_2002.pcap");
  fs::create_directories(raw / "pandarcap_20261127T220805Z_2003.pcap");
  make_backlog_file(frames / "frame_000001_20261127T220805.000Z.pcd", 7000, 10);

  UploadBacklog backlog(true);
  backlog.watch(raw);
  backlog.watch(mcap);
  backlog.watch(dir / "gone");  // an upload directory that is not there
  UploadGauges g;
  backlog.fill(5000 * kNs, g);
  CHECK(g.enabled);
  CHECK_FALSE(g.known);  // before the first pass has ended
  // No time at all for each step: 64 files a step, the figures published only when the pass ends.
  int steps = 1;
  backlog.step(0);
  backlog.fill(5000 * kNs, g);
  CHECK_FALSE(g.known);
  while (!g.known && steps < 100) {
    backlog.step(0);
    ++steps;
    backlog.fill(5000 * kNs, g);
  }
  CHECK(steps == static_cast<int>((files + 63) / 64));  // every step read on from the last
  CHECK(g.backlog_files == files);
  CHECK(g.backlog_bytes == bytes);
  CHECK(g.oldest_seconds == Approx(4000));
  // The upload moves the oldest 100 recordings (with their sidecars) away: the next pass says so.
  for (int i = 0; i < 100; ++i) {
    const std::string stem = "pandarcap_20261127T220805Z_" + std::to_string(1000 + i);
    for (const char* suffix : {".pcap.zst", ".calibration.csv", ".sensor.json"})
      fs::remove(raw / (stem + suffix));
    bytes -= 100 + i + 30;
    files -= 3;
  }
  backlog.prepare();  // a whole pass at once, as at start-up
  backlog.fill(5000 * kNs, g);
  CHECK(g.backlog_files == files);
  CHECK(g.backlog_bytes == bytes);
  CHECK(g.oldest_seconds == Approx(3900));
  // The clock set back before the files' times: nothing waits a negative time.
  backlog.fill(500 * kNs, g);
  CHECK(g.oldest_seconds == 0);

  // The floor removes one before it was uploaded: counted, named, out of the figures at once.
  const fs::path victim = raw / "pandarcap_20261127T220805Z_1100.pcap.zst";
  backlog.removed(victim.native(), 200, UploadBacklog::Remover::kFloor);
  CHECK(backlog.files_removed_before_upload() == 1);
  CHECK(backlog.bytes_removed_before_upload() == 200);
  backlog.fill(5000 * kNs, g);
  CHECK(g.backlog_files == files - 1);
  CHECK(std::string(g.last_removed) == "pandarcap_20261127T220805Z_1100.pcap.zst");
  CHECK(g.last_removed_by_floor);
  // Retention, in mcap/: the same. Not ours, or outside the upload directories: nothing.
  backlog.removed((mcap / "pandarcap_20261127T220805Z_0000.mcap").native(), 5000,
                  UploadBacklog::Remover::kRetention);
  backlog.removed((raw / "notes.txt").native(), 7000, UploadBacklog::Remover::kRetention);
  backlog.removed((frames / "frame_000001_20261127T220805.000Z.pcd").native(), 7000,
                  UploadBacklog::Remover::kFloor);
  CHECK(backlog.files_removed_before_upload() == 2);
  CHECK(backlog.bytes_removed_before_upload() == 5200);
  backlog.fill(5000 * kNs, g);
  CHECK(std::string(g.last_removed) == "pandarcap_20261127T220805Z_0000.mcap");
  CHECK_FALSE(g.last_removed_by_floor);

  // The directories vanish (a disk pulled): nothing waits.
  fs::remove_all(raw);
  fs::remove_all(mcap);
  backlog.prepare();
  backlog.fill(5000 * kNs, g);
  CHECK(g.known);
  CHECK(g.backlog_files == 0);
  CHECK(g.backlog_bytes == 0);
  CHECK(g.oldest_seconds == 0);

  // Without output.upload the figures are there, but nothing removed counts as before upload.
  UploadBacklog off(false);
  off.watch(raw);
  off.removed(victim.native(), 200, UploadBacklog::Remover::kFloor);
  CHECK(off.files_removed_before_upload() == 0);
  off.fill(0, g);
  CHECK_FALSE(g.enabled);
}

TEST_CASE("Upload: the reason names the file removed before it was uploaded, and the formats",
          "[upload]") {
  HealthCounters before, now;
  now.files_removed_before_upload = 1;
  now.bytes_removed_before_upload = 9'000'000;
  HealthGauges g;
  g.return_mode = "dual";
  g.seconds_since_last_packet = 0.1;
  const std::string name = "pandarcap_20261127T220805Z_0003.pcap.zst";
  std::copy(name.begin(), name.end(), g.storage.upload.last_removed);
  g.storage.upload.last_removed_by_floor = true;
  classify_health(now, before, HealthExpectations{}, false, "", g);
  CHECK(g.state == HealthState::kDegraded);
  CHECK(g.reason ==
        "1 file removed before it was uploaded (9.0 MB; the last by the free-space floor: "
        "pandarcap_20261127T220805Z_0003.pcap.zst)");
  before = now;  // nothing more the next second: ok again
  classify_health(now, before, HealthExpectations{}, false, "", g);
  CHECK(g.state == HealthState::kOk);

  HealthSnapshot h;
  h.sensor = "front";
  h.counters = now;
  UploadGauges& up = h.gauges.storage.upload;
  up.enabled = up.known = true;
  up.backlog_bytes = 9'000'000'000;
  up.backlog_files = 3;
  up.oldest_seconds = 5400.5;
  const json j = json::parse(to_json_line(h));
  CHECK(j.at("storage").at("upload") ==
        json::parse(R"({"enabled":true,"backlog_bytes":9000000000,"backlog_files":3,)"
                    R"("oldest_seconds":5400.5})"));
  CHECK(j.at("counters").at("files_removed_before_upload") == 1);
  CHECK(j.at("counters").at("bytes_removed_before_upload") == 9'000'000);
  auto prom = test::prom_samples(to_prometheus(h));
  CHECK(prom.at("pandarcap_storage_upload_backlog_bytes{sensor=\"front\"}") == "9000000000");
  CHECK(prom.at("pandarcap_storage_upload_backlog_files{sensor=\"front\"}") == "3");
  CHECK(prom.at("pandarcap_storage_upload_oldest_seconds{sensor=\"front\"}") == "5400.5");
  CHECK(prom.at("pandarcap_files_removed_before_upload_total{sensor=\"front\"}") == "1");
  CHECK(prom.at("pandarcap_removed_before_upload_bytes_total{sensor=\"front\"}") == "9000000");
  if (test::run_command("command -v promtool >/dev/null").exit_code == 0) {
    test::ScratchDir dir("upload-prom");
    std::ofstream(dir / "pandarcap.prom") << to_prometheus(h);
    std::string said;
    const bool accepted = test::promtool_accepts(dir / "pandarcap.prom", said);
    INFO(said);
    CHECK(accepted);
  }
  // Upload off: the JSON still has the figures (the recordings kept here), the .prom has no
  // backlog gauges (an alert on their age would fire for every instance that does not upload).
  up.enabled = false;
  CHECK(json::parse(to_json_line(h)).at("storage").at("upload").at("backlog_bytes") ==
        9'000'000'000);
  prom = test::prom_samples(to_prometheus(h));
  CHECK(prom.count("pandarcap_storage_upload_backlog_bytes{sensor=\"front\"}") == 0);
  // Before the first pass: nulls.
  up.known = false;
  CHECK(json::parse(to_json_line(h)).at("storage").at("upload").at("backlog_bytes").is_null());
}
