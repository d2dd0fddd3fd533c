// Recordings that carry what decodes them: one run of the simulated sensor (whose calibration is
// not the nominal one: laser 1 at 15.118 degrees, nominal 15) recorded as pcap.zst and MCAP,
// then replayed as pcap, pcap.zst and MCAP without --calibration: the recording's own table is
// taken (calibration_source "recording") and every complete frame equals the live run's. What
// the files say of where they were made (the MCAP "foxglove" and "pandarcap" metadata read by
// @mcap/core, raw/sensor.json), what an unusable or missing table does, and the replay's progress
// line on a terminal only.
#include <fmt/format.h>

#include <catch2/catch.hpp>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "bench/child_process.hpp"
#include "core/progress_line.hpp"
#include "daemon/pcap/recording_sidecars.hpp"
#include "daemon/pcap/xxh64.hpp"
#include "support/mcap_reader.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
using nlohmann::json;
namespace fs = std::filesystem;
using test::quoted;

namespace {

// The complete frames of an output directory: file name -> bytes.
std::map<std::string, std::string> complete_frames(const fs::path& out) {
  std::map<std::string, std::string> frames;
  for (const fs::path& pcd : test::files_ending(out / "frames", ".pcd")) {
    const std::string name = pcd.filename().string();
    if (name.find("partial") == std::string::npos) frames[name] = harness::read_file(pcd);
  }
  return frames;
}

test::CommandResult replay_recording(const fs::path& recording, const fs::path& out,
                                     const std::string& extra = "") {
  return test::run_command(test::pandarcapd_command() + " --replay " + quoted(recording) + " " +
                           extra + " --output-dir " + quoted(out) + " 2>&1");
}

// One live run of the simulated sensor, recorded (pcap.zst, MCAP with packets), shared by the
// test cases below.
struct CalibrationRecorded {
  CalibrationRecorded() : dir("recording-calibration") {
    std::ofstream(dir / "rig.toml") << "[output]\ndevice_name = \"test-rig-7\"\n";
    const std::string args = " -c " + quoted(dir / "rig.toml") +
                             " --pcap-compression zstd --mcap --mcap-packets --output-dir " +
                             quoted(dir / "live");
    const auto run = test::run_command(test::pandarcapd_command() + " --simulate --duration 1.5" +
                                       args + " 2>&1");
    INFO(run.out);
    REQUIRE(run.exit_code == 0);
    printed_config = test::run_command(test::pandarcapd_command() + args + " --print-config").out;
    const auto zst = test::files_ending(dir / "live" / "raw", ".pcap.zst");
    REQUIRE(zst.size() == 1);
    pcap_zst = zst.front();
    // The same recording uncompressed, with the same stem.
    pcap = dir / "plain" / pcap_zst.filename().replace_extension("");
    fs::create_directories(pcap.parent_path());
    REQUIRE(
        test::run_command("zstd -q -d -c " + quoted(pcap_zst) + " > " + quoted(pcap)).exit_code ==
        0);
    const auto mcaps = test::files_ending(dir / "live" / "mcap", ".mcap");
    REQUIRE(mcaps.size() == 1);
    mcap = mcaps.front();
    live_health = test::last_health_record(dir / "live");
    // The daemon put the recording's calibration beside it (STEM.calibration.csv: the table
    // of raw/calibration.csv); the uncompressed copy the test made gets a copy of it.
    const fs::path sidecar = recording_sidecars(pcap_zst.string())->calibration_csv;
    REQUIRE(fs::exists(sidecar));
    CHECK(harness::read_file(sidecar) ==
          harness::read_file(dir / "live" / "raw" / "calibration.csv"));
    fs::copy_file(sidecar, recording_sidecars(pcap.string())->calibration_csv);
  }
  test::ScratchDir dir;
  fs::path pcap, pcap_zst, mcap;
  std::string printed_config;
  // The live run's last health record: what it left out of each recording, counted (left_out).
  json live_health;

  // What the live run left out of `recording` and counted. On a loaded machine (a sanitizer's)
  // the MCAP's compression can fall a pool behind, and the MCAP then lacks the packets of a few
  // frames; the writer can run out of raw batches, and the pcap lacks packets (or lost them to
  // failed writes). Those frames are whole in the live run and have holes in the replay.
  std::uint64_t left_out(const fs::path& recording) const {
    if (recording == mcap) {
      return test::health_counter(live_health, "mcap_messages_not_recorded") +
             test::health_counter(live_health, "mcap_messages_not_written");
    }
    return test::health_counter(live_health, "packets_not_recorded");
  }
};

CalibrationRecorded& recorded() {
  static CalibrationRecorded r;
  return r;
}

}  // namespace

namespace {

void replay_the_three(CalibrationRecorded& r) {
  const auto live = complete_frames(r.dir / "live");
  // 1.5 s of the simulated sensor: about 14 complete frames. A sanitizer build's simulated sensor,
  // starved on a loaded machine, sends as little as a third of that in the time (its clock then
  // behind the host's): two frames still compare the replays with the live run.
  INFO("the live run's last health: " << r.live_health.dump());
  REQUIRE(live.size() >= (test::kSlowBuild ? 2U : 5U));
  const std::string nominal = harness::read_file(r.dir / "live" / "raw" / "calibration.csv");
  REQUIRE(nominal.find("15.118") != std::string::npos);  // not the nominal table (15)

  for (const fs::path& recording : {r.pcap, r.pcap_zst, r.mcap}) {
    INFO(recording.filename());
    const fs::path out = r.dir / ("replay-" + recording.filename().string());
    const auto run = replay_recording(recording, out);
    INFO(run.out);
    REQUIRE(run.exit_code == 0);
    CHECK(run.out.find("calibration: from the recording: ") != std::string::npos);
    const json last = test::last_health_record(out);
    CHECK(last["sensor_info"]["calibration_source"] == "recording");
    const auto frames = complete_frames(out);
    // Every complete frame of the replay is the live run's, byte for byte (the replay may cut
    // one more or one fewer at the ends, where the live run's frames were partial). Where the
    // live run left packets out of the recording (counted: a sanitizer build's writer and
    // compression fall behind on a loaded machine), that replay lacks the frames they were in:
    // its frames are compared, not counted.
    const bool is_mcap = recording == r.mcap;
    const std::uint64_t left_out = r.left_out(recording);
    const bool all_recorded = left_out == 0;
    INFO("messages or packets the live run left out of it: " << left_out);
    // A pcap holds every datagram the live run received but those it counted as left out (and,
    // under ThreadSanitizer, those the ring overran: check_ring_overruns), and a build that is
    // not slowed keeps up with the simulated sensor.
    if (!is_mcap) {
      if (!test::kSlowBuild) CHECK(left_out == 0);
      CHECK(test::health_counter(last, "datagrams_received") + left_out +
                test::check_ring_overruns(r.live_health) ==
            test::health_counter(r.live_health, "datagrams_received"));
    }
    const std::size_t expected = all_recorded ? live.size() - 1 : 1;
    REQUIRE(frames.size() >= expected);
    std::size_t same = 0;
    for (const auto& [name, bytes] : frames) {
      const auto it = live.find(name);
      if (it == live.end()) continue;
      CHECK(bytes == it->second);
      ++same;
    }
    CHECK(same >= expected);
    // pandarcap-inspect takes the same table.
    const auto inspect = test::run_command(test::binary("pandarcap-inspect").string() +
                                           " --json --summary " + quoted(recording));
    REQUIRE(inspect.exit_code == 0);
    CHECK(json::parse(inspect.out)["summary"]["calibration_source"] == "recording");
  }
}

void check_metadata(CalibrationRecorded& r) {
  Xxh64 hash;
  hash.update(
      {reinterpret_cast<const std::uint8_t*>(r.printed_config.data()), r.printed_config.size()});
  const std::string config_hash = fmt::format("xxh64:{:016x}", hash.digest());
  REQUIRE(r.printed_config.find("device_name = \"test-rig-7\"") != std::string::npos);

  const json sensor = json::parse(harness::read_file(r.dir / "live" / "raw" / "sensor.json"));
  CHECK(sensor["device_name"] == "test-rig-7");
  CHECK(sensor["config_hash"] == config_hash);

  const auto read = test::read_mcap_independently(r.mcap);
  if (read.reader_missing) return;
  REQUIRE(read.file);
  std::map<std::string, json> metadata;
  for (const json& m : (*read.file)["metadata"])
    metadata[m["name"]] = m["entries"];
  REQUIRE(metadata.count("foxglove") == 1);
  CHECK(metadata["foxglove"]["deviceName"] == "test-rig-7");
  REQUIRE(metadata.count("pandarcap") == 1);
  const json& p = metadata["pandarcap"];
  CHECK(p["device_name"] == "test-rig-7");
  CHECK(p["config_hash"] == config_hash);
  CHECK(p["calibration_source"] == "sensor");
  // The sensor facts: raw/sensor.json's content.
  const json facts = json::parse(p["sensor_json"].get<std::string>());
  CHECK(facts == sensor);
  CHECK(facts["inventory"]["serial"] == p["sensor_serial"]);
}

void check_hostile_tables(CalibrationRecorded& r) {
  const fs::path dir = r.dir / "hostile";
  fs::create_directories(dir);
  const std::string csv = harness::read_file(r.dir / "live" / "raw" / "calibration.csv");
  const fs::path pcap = dir / "x.pcap";
  fs::copy_file(r.pcap, pcap);
  const fs::path sidecar = dir / "x.calibration.csv";

  // Another model's table (64 lasers), and a file that is not a calibration CSV: exit 78, the
  // sidecar named; never the nominal table in silence.
  std::string bigger = csv;
  for (int laser = 41; laser <= 64; ++laser)
    bigger += std::to_string(laser) + ",1.0,0.0\n";
  for (const std::string& content : {bigger, std::string("\x89PNG\r\n\x1a\n not a table")}) {
    std::ofstream(sidecar, std::ios::trunc) << content;
    const auto run = replay_recording(pcap, dir / "out-bad");
    INFO(run.out);
    CHECK(run.exit_code == 78);
    CHECK(run.out.find(sidecar.string()) != std::string::npos);
  }
  // None beside it: the nominal table, with a warning naming where it looked.
  fs::remove(sidecar);
  const auto run = replay_recording(pcap, dir / "out-none");
  INFO(run.out);
  CHECK(run.exit_code == 0);
  CHECK(run.out.find("[warning] calibration: the recording carries none (looked for " +
                     sidecar.string()) != std::string::npos);
  CHECK(test::last_health_record(dir / "out-none")["sensor_info"]["calibration_source"] ==
        "nominal");
  // --calibration comes first, whatever the recording carries.
  std::ofstream(sidecar) << bigger;
  const auto given =
      replay_recording(pcap, dir / "out-given",
                       "--calibration " + quoted(r.dir / "live" / "raw" / "calibration.csv"));
  INFO(given.out);
  CHECK(given.exit_code == 0);
  CHECK(test::last_health_record(dir / "out-given")["sensor_info"]["calibration_source"] == "file");

  // An MCAP file whose attachment is damaged: exit 78, named.
  std::string bytes = harness::read_file(r.mcap);
  const std::size_t at = bytes.find("Laser id");
  REQUIRE(at != std::string::npos);
  bytes[at + 20] = static_cast<char>(bytes[at + 20] ^ 0x01);
  std::ofstream(dir / "damaged.mcap", std::ios::binary) << bytes;
  const auto damaged = replay_recording(dir / "damaged.mcap", dir / "out-mcap");
  INFO(damaged.out);
  CHECK(damaged.exit_code == 78);
  CHECK(damaged.out.find("(attachment calibration.csv): damaged") != std::string::npos);
}

}  // namespace

// One TEST_CASE (one live run), in sections.
TEST_CASE("recordings carry their calibration and where they were made",
          "[daemon][replay][recording][mcap][threads]") {
  CalibrationRecorded& r = recorded();
  SECTION("a replay without --calibration takes the recording's own: frames equal the live run's") {
    replay_the_three(r);
  }
  SECTION("what the recordings say of where they were made: MCAP metadata and sensor.json") {
    check_metadata(r);
  }
  SECTION("a recording's table that cannot be used stops the replay; none is the nominal, said") {
    check_hostile_tables(r);
  }
}

TEST_CASE("a replay's progress shows on a terminal, never in a pipe or the journal",
          "[daemon][replay][threads]") {
  if (test::run_command("command -v script >/dev/null").exit_code != 0) {
    WARN("script(1) is not installed: the terminal is not tried");
    return;
  }
  test::ScratchDir dir("replay-progress");
  // A second of the simulated sensor replayed at twice its pace, the quiet start shortened (a
  // test hook: a real one waits 2 s before its first line).
  const fs::path capture =
      test::write_simulated_recording(dir / "second.pcap", 3600, 1'677'657'600'000'000'000,
                                      Endpoint{0xC0A801C9, 2368}, Endpoint{0xC0A8010A, 2368});
  const std::string command = "PANDARCAP_TEST_PROGRESS_QUIET_S=0 " + test::pandarcapd_command() +
                              " --replay " + quoted(capture) + " --rate 2 --output-dir " +
                              quoted(dir / "out");
  const auto tty = test::run_command("script -qec \"" + command + "\" /dev/null");
  INFO(tty.out);
  CHECK(tty.exit_code == 0);
  CHECK(tty.out.find("replay: ") != std::string::npos);
  CHECK(tty.out.find("% (") != std::string::npos);
  CHECK(tty.out.find(" packets/s") != std::string::npos);
  CHECK(tty.out.find(" s left") != std::string::npos);
  // systemd's journal (JOURNAL_STREAM) and a pipe: not a line.
  for (const std::string& run :
       {"script -qec \"JOURNAL_STREAM=8:1 " + command + "\" /dev/null", command + " 2>&1"}) {
    const auto quiet = test::run_command(run);
    INFO(quiet.out);
    CHECK(quiet.exit_code == 0);
    CHECK(quiet.out.find(" packets/s") == std::string::npos);
    CHECK(quiet.out.find("% (") == std::string::npos);
  }
}

TEST_CASE("the progress line: quiet at first, then percent, rate and time left", "[replay]") {
  ProgressLine progress(2.0, 0.5);
  CHECK_FALSE(progress.update(1.9, 10, 100, 1000));
  CHECK_FALSE(progress.shown());
  const auto line = progress.update(2.0, 25'000'000, 100'000'000, 36'000);
  REQUIRE(line);
  CHECK(*line == "replay: 25% (25.0 of 100.0 MB), 18000 packets/s, 6 s left");
  CHECK(progress.shown());
  CHECK_FALSE(progress.update(2.4, 30'000'000, 100'000'000, 40'000));  // within the interval
  CHECK(*progress.update(60.0, 20'000'000, 100'000'000, 36'000) ==
        "replay: 20% (20.0 of 100.0 MB), 600 packets/s, 4 min left");
  CHECK(*progress.update(61.0, 200, 100, 36'000) ==
        "replay: 100% (0.0 of 0.0 MB), 590 packets/s, 0 s left");
  CHECK_FALSE(ProgressLine().update(5.0, 0, 0, 0));  // no size: nothing to say
}
