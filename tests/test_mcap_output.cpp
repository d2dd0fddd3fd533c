// pandarcapd's MCAP output end to end: the real binary, real sockets and files, read back by the
// MCAP project's own reader (support/mcap_reader.hpp) and compared with the PCD files, the pcap
// and health.jsonl of the same run.
#include <fmt/format.h>
#include <signal.h>

#include <algorithm>
#include <catch2/catch.hpp>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "bench/child_process.hpp"
#include "core/frames/pcd.hpp"
#include "support/mcap_reader.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
using namespace std::chrono_literals;
namespace fs = std::filesystem;
using nlohmann::json;
using test::quoted;

namespace {

// Runs pandarcapd with `args` and a configuration of `toml`; returns its exit status and output.
// The PCD files are written in the layout the MCAP messages carry (pandarcap's), so the two can
// be compared point for point.
test::CommandResult run_daemon(const test::ScratchDir& dir, const std::string& toml,
                               const std::string& args) {
  const fs::path config = dir / "pandarcap.toml";
  std::ofstream(config) << toml;
  return test::run_command(test::pandarcapd_command() + " -c " + quoted(config) +
                           " --pcd-fields pandarcap " + args + " 2>&1");
}

// The reader's view of one point against a PCD point: the same bytes, so exactly equal.
void check_point(const json& m, const PcdPoint& p) {
  CHECK(m["x"].get<float>() == p.x);
  CHECK(m["y"].get<float>() == p.y);
  CHECK(m["z"].get<float>() == p.z);
  CHECK(m["intensity"] == p.intensity);
  CHECK(m["channel"] == p.channel);
  CHECK(m["return_type"] == p.return_type);
  CHECK(m["timestamp"].get<double>() == p.timestamp_s);
}

// A PointCloud2's header.stamp in seconds: the frame's first firing.
double message_stamp(const json& m) {
  return m["stamp"]["sec"].get<double>() + m["stamp"]["nanosec"].get<double>() * 1e-9;
}

// The PCD file each PointCloud2 of `messages` is, matched in order by its stamp (the PCD header's
// frame_reference_time). A live run leaves out, and counts, a frame's message that finds every
// chunk buffer in flight (a compressor behind on a busy machine) while its PCD is still written:
// at most `left_out` PCDs may have no message; a replay waits instead, so it passes 0.
std::vector<fs::path> pcds_of_messages(const json& messages, const std::vector<fs::path>& pcds,
                                       std::uint64_t left_out) {
  REQUIRE(messages.size() <= pcds.size());
  CHECK(pcds.size() - messages.size() <= left_out);
  std::vector<fs::path> matched;
  std::size_t next = 0;
  for (std::size_t i = 0; i < messages.size(); ++i) {
    const double stamp = message_stamp(messages[i]);
    bool found = false;
    for (; next < pcds.size() && !found; ++next) {
      found = std::abs(test::pcd_reference_time(pcds[next]) - stamp) <= 1e-6;
      if (found) matched.push_back(pcds[next]);
    }
    INFO("message " << i << " at " << fmt::format("{:.9f}", stamp));
    REQUIRE(found);  // every message is one PCD's frame, in the PCDs' order
  }
  return matched;
}

// Every PointCloud2 of `file` against its PCD file (pcds_of_messages): point counts, the first
// and last point exactly, and the sums of x, y, z.
void check_frames_equal_pcd(const json& file, const std::vector<fs::path>& pcds,
                            std::uint64_t left_out) {
  const json& messages = file["topics"]["/pandar/points"]["messages"];
  const std::vector<fs::path> matched = pcds_of_messages(messages, pcds, left_out);
  for (std::size_t i = 0; i < messages.size(); ++i) {
    INFO("frame " << i << ": " << matched[i].filename().string());
    const std::vector<PcdPoint> points = test::pandarcap_pcd_points(matched[i]);
    const json& m = messages[i];
    REQUIRE(m["points"] == points.size());
    if (points.empty()) continue;
    check_point(m["first"], points.front());
    check_point(m["last"], points.back());
    double sx = 0, sy = 0, sz = 0;
    for (const PcdPoint& p : points) {
      sx += p.x;
      sy += p.y;
      sz += p.z;
    }
    CHECK(m["sums"]["x"].get<double>() == Approx(sx).epsilon(1e-9));
    CHECK(m["sums"]["y"].get<double>() == Approx(sy).epsilon(1e-9));
    CHECK(m["sums"]["z"].get<double>() == Approx(sz).epsilon(1e-9));
    // header.stamp: the frame's first firing, no later than its first point.
    CHECK(message_stamp(m) <= points.front().timestamp_s + 1e-6);
  }
}

json read_or_fail(const fs::path& file) {
  const auto read = test::read_mcap_independently(file);
  if (read.reader_missing) return json();
  INFO(file.string() << ": " << read.error);
  REQUIRE(read.file);
  return *read.file;
}

}  // namespace

TEST_CASE(
    "a simulated run with MCAP: frames, packets, health and calibration, as the other outputs",
    "[daemon][mcap][realtime][threads]") {
  test::ScratchDir dir("mcap-simulate");
  const fs::path out = dir / "out";
  const auto r =
      run_daemon(dir,
                 "[output]\nmcap = true\nmcap_packets = true\n"
                 "mcap_frame_id = \"lidar_front\"\nmcap_points_topic = \"/front/points\"\n",
                 "--simulate --duration 3 --output-dir " + quoted(out));
  INFO(r.out);
  REQUIRE(r.exit_code == 0);
  CHECK(r.out.find("  mcap    " + (out / "mcap").string()) != std::string::npos);
  const auto files = test::files_ending(out / "mcap", ".mcap");
  REQUIRE(files.size() == 1);
  CHECK(test::files_ending(out / "mcap", ".part").empty());
  const json h = test::last_health_record(out);
  json file = read_or_fail(files[0]);
  if (file.is_null()) return;
  INFO(file["statistics"].dump());

  CHECK(file["header"]["profile"] == "ros2");
  CHECK(file["header"]["library"].get<std::string>().starts_with("pandarcap "));
  // The topic names and frame id configured; the health topic's default.
  json points = file["topics"]["/front/points"];
  REQUIRE(points.is_object());
  file["topics"]["/pandar/points"] = points;  // for check_frames_equal_pcd
  CHECK(points["messages"][0]["frame_id"] == "lidar_front");
  const auto pcds = test::files_ending(out / "frames", ".pcd");
  CHECK(pcds.size() == test::health_counter(h, "frames_written"));
  // What the MCAP file itself left out, each counted: the messages that found every chunk buffer
  // in flight (a compressor behind on a busy machine). The rest of mcap_messages_not_recorded
  // are the datagrams with no raw batch, missing from the pcap as well.
  const std::uint64_t pcap_not_recorded = test::health_counter(h, "pcap_packets_not_recorded");
  const std::uint64_t mcap_not_recorded = test::health_counter(h, "mcap_messages_not_recorded");
  REQUIRE(mcap_not_recorded >= pcap_not_recorded);
  const std::uint64_t left_out = mcap_not_recorded - pcap_not_recorded;
  check_frames_equal_pcd(file, pcds, left_out);

  // Every datagram, as in the pcap, less those the MCAP file left out (the frames' and the
  // packets' together no more than it counted).
  const auto pcaps = test::files_ending(out / "raw", ".pcap");
  REQUIRE(pcaps.size() == 1);
  const auto [status, records] = test::read_capture(pcaps[0]);
  const auto packets = file["topics"]["/pandar/packets"]["count"].get<std::uint64_t>();
  REQUIRE(packets <= records);
  CHECK((records - packets) + (pcds.size() - points["messages"].size()) <= left_out);
  // Sanitizer builds: less what was counted as not recorded (see kSlowBuild) and, under
  // ThreadSanitizer, overrun by the ring (check_ring_overruns).
  const std::uint64_t overruns = test::check_ring_overruns(h);
  CHECK(records + (test::kSlowBuild ? pcap_not_recorded : 0) + overruns ==
        test::health_counter(h, "datagrams_received"));
  CHECK(file["topics"]["/pandar/packets"]["messages"][0]["size"] == 1262);
  CHECK(file["topics"]["/pandar/packets"]["messages"][0]["first_bytes"] ==
        json::array({0xFF, 0xEE}));  // the first block's marker

  // A health message per health.jsonl line written while the file was open, the last one the
  // final record.
  const json& health = file["topics"]["/pandar/health"];
  CHECK(health["count"].get<int>() >= 3);
  CHECK(health["messages"].back()["state"] == h["state"]);
  CHECK(health["messages"].back()["datagrams_received"] ==
        test::health_counter(h, "datagrams_received"));

  // The calibration in use, as saved beside the pcap.
  REQUIRE(file["attachments"].size() == 1);
  CHECK(file["attachments"][0]["name"] == "calibration.csv");
  CHECK(file["attachments"][0]["text"] == harness::read_file(out / "raw" / "calibration.csv"));
  CHECK(file["metadata"][0]["name"] == "pandarcap");
  CHECK(file["metadata"][0]["entries"].contains("decoder"));

  // The health counters agree with the file. The last health.jsonl record was written before
  // its own MCAP message and the file's tail; the exit summary counts both.
  const auto messages = file["statistics"]["message_count"].get<std::uint64_t>();
  CHECK(test::health_counter(h, "mcap_messages_written") == messages - 1);
  CHECK(test::health_counter(h, "mcap_messages_not_written") == 0);
  CHECK(test::health_counter(h, "mcap_bytes_written") > 0);
  CHECK(test::health_counter(h, "mcap_bytes_written") < fs::file_size(files[0]));
  // None left out, but in a slow build: the datagrams with no raw batch and what the file left
  // out, both checked above.
  if (!test::kSlowBuild) CHECK(mcap_not_recorded == 0);
  CHECK(r.out.find(fmt::format(
            "mcap: {} messages written, 0 not written, {} not recorded, {} bytes", messages,
            mcap_not_recorded, fs::file_size(files[0]))) != std::string::npos);
}

TEST_CASE("a replay with --mcap-only converts the real capture: the same frames as its PCDs",
          "[daemon][mcap][real][threads]") {
  const auto capture = test::real_capture("pandar40p_nebula_dual_600rpm_1262B.pcap");
  if (!capture) return;
  test::ScratchDir dir("mcap-convert");
  // The PCDs in the MCAP messages' layout, so the two compare point for point.
  const std::string replay =
      test::pandarcapd_command() + " --pcd-fields pandarcap --replay " + quoted(*capture);
  const auto pcd = test::run_command(replay + " --output-dir " + quoted(dir / "pcd") + " 2>&1");
  REQUIRE(pcd.exit_code == 0);
  const auto r = test::run_command(replay + " --mcap-only --output-dir " +
                                   quoted(dir / "mcap-only") + " 2>&1");
  INFO(r.out);
  REQUIRE(r.exit_code == 0);
  CHECK_FALSE(fs::exists(dir / "mcap-only" / "frames"));
  CHECK_FALSE(fs::exists(dir / "mcap-only" / "raw"));
  const auto files = test::files_ending(dir / "mcap-only" / "mcap", ".mcap");
  REQUIRE(files.size() == 1);
  const json file = read_or_fail(files[0]);
  if (file.is_null()) return;
  const auto pcds = test::files_ending(dir / "pcd" / "frames", ".pcd");
  REQUIRE_FALSE(pcds.empty());
  check_frames_equal_pcd(file, pcds, 0);
  CHECK_FALSE(file["topics"].contains("/pandar/packets"));
  // Log times are the capture's, not the host's clock at conversion: the file plays back at the
  // pace it was recorded, and health messages stay inside the recording's time range.
  const std::uint64_t start =
      std::stoull(file["statistics"]["message_start_time"].get<std::string>());
  const std::uint64_t end = std::stoull(file["statistics"]["message_end_time"].get<std::string>());
  const auto now_ns =
      static_cast<std::uint64_t>(std::chrono::duration_cast<std::chrono::nanoseconds>(
                                     std::chrono::system_clock::now().time_since_epoch())
                                     .count());
  // The capture's record times (2023-01-11, 1.2 s of it), not the sensor's clock (2017).
  CHECK(start >= 1'673'400'149'000'000'000ull);
  CHECK(end - start < 3'000'000'000ull);
  CHECK(now_ns - end > 3600'000'000'000ull);  // recorded long before this test ran
}

// arenas.points_per_frame below a revolution: the arenas take what the model needs
// (arena_points), and so must the MCAP messages and the lzf compressor, or every frame that fills
// more than was asked is refused, counted as a write error.
TEST_CASE("a small arenas.points_per_frame: every frame still reaches the MCAP and the lzf PCDs",
          "[daemon][mcap][real][threads]") {
  const auto capture = test::real_capture("pandar40p_nebula_dual_600rpm_1262B.pcap");
  if (!capture) return;
  test::ScratchDir dir("mcap-small-arenas");
  std::ofstream(dir / "small.toml") << "[arenas]\npoints_per_frame = 1000\n"
                                       "[output]\npcd_compression = \"lzf\"\n";
  const auto r = test::run_command(
      test::pandarcapd_command() + " -c " + quoted(dir / "small.toml") + " --mcap --replay " +
      quoted(*capture) + " --output-dir " + quoted(dir / "out") + " 2>&1");
  INFO(r.out);
  REQUIRE(r.exit_code == 0);
  const json h = test::last_health_record(dir / "out");
  INFO(h.dump());
  CHECK(test::health_counter(h, "write_errors") == 0);
  CHECK(test::health_counter(h, "mcap_messages_not_written") == 0);
  CHECK(test::health_counter(h, "mcap_messages_not_recorded") == 0);
  const auto pcds = test::files_ending(dir / "out" / "frames", ".pcd");
  REQUIRE(pcds.size() >= 3);  // the capture is 1.2 s
  const auto files = test::files_ending(dir / "out" / "mcap", ".mcap");
  REQUIRE(files.size() == 1);
  const json file = read_or_fail(files[0]);
  if (file.is_null()) return;
  // One point cloud per PCD written.
  CHECK(file["topics"]["/pandar/points"]["messages"].size() == pcds.size());
}

TEST_CASE("a killed run's MCAP, cut anywhere, is finished at the next start for the reader",
          "[daemon][mcap][recovery][threads]") {
  test::ScratchDir dir("mcap-killed");
  const fs::path out = dir / "out";
  const fs::path config = dir / "pandarcap.toml";
  std::ofstream(config) << "[output]\nmcap = true\nmcap_chunk_bytes = 65536\n";
  std::optional<harness::ChildProcess> daemon;
  daemon.emplace(test::binary("pandarcapd"),
                 std::vector<std::string>{"--allow-root", "-c", config.string(), "--simulate",
                                          "--output-dir", out.string()},
                 dir / "log.txt");
  // Killed once the file holds a few seconds' chunks.
  const auto part_size = [&]() -> std::uintmax_t {
    const auto parts = test::files_ending(out / "mcap", ".part");
    std::error_code ec;
    return parts.empty() ? 0 : fs::file_size(parts[0], ec);
  };
  REQUIRE(harness::wait_until([&] { return part_size() > 4'000'000; }, 30s));
  daemon->signal(SIGKILL);
  REQUIRE(daemon->wait_exit(10s));
  daemon.reset();
  const auto parts = test::files_ending(out / "mcap", ".part");
  REQUIRE(parts.size() == 1);
  // And cut at a random offset past its first chunk, as a power loss mid-write leaves it.
  std::mt19937 rng(std::random_device{}());
  const std::uintmax_t size = fs::file_size(parts[0]);
  const std::uintmax_t cut = size / 4 + rng() % (size - size / 4);
  INFO("cut at " << cut << " of " << size);
  fs::resize_file(parts[0], cut);

  const auto r =
      test::run_command(test::pandarcapd_command() + " -c " + quoted(config) +
                        " --simulate --duration 1 --output-dir " + quoted(out) + " 2>&1");
  INFO(r.out);
  REQUIRE(r.exit_code == 0);
  CHECK(test::files_ending(out / "mcap", ".part").empty());
  const auto files = test::files_ending(out / "mcap", ".mcap");
  REQUIRE(files.size() == 2);  // the recovered one, this run's
  const fs::path recovered = parts[0].parent_path() / parts[0].stem();  // NAME.mcap
  REQUIRE(fs::exists(recovered));
  CHECK(fs::file_size(recovered) < cut + 1'000'000);
  const json file = read_or_fail(recovered);
  if (file.is_null()) return;
  CHECK(file["statistics"]["message_count"].get<int>() > 0);
  CHECK(file["topics"]["/pandar/points"]["count"].get<int>() > 0);
  CHECK(file["attachments"][0]["name"] == "calibration.csv");
  read_or_fail(files[0] == recovered ? files[1] : files[0]);
}

TEST_CASE("MCAP files rotate by size and are kept to mcap_max_files across runs",
          "[daemon][mcap][outputs][threads]") {
  test::ScratchDir dir("mcap-rotate");
  const fs::path out = dir / "out";
  const std::string toml =
      "[output]\nmcap = true\nframes = false\npcap = false\nmcap_chunk_bytes = 65536\n"
      "mcap_rotate_bytes = 3000000\nmcap_max_files = 3\n";
  for (int run = 0; run < 2; ++run) {
    const auto r = run_daemon(dir, toml, "--simulate --duration 2 --output-dir " + quoted(out));
    INFO(r.out);
    REQUIRE(r.exit_code == 0);
  }
  const auto files = test::files_ending(out / "mcap", ".mcap");
  CHECK(files.size() == 3);
  for (const fs::path& f : files) {
    INFO(f.string());
    CHECK(fs::file_size(f) < 3'000'000 + 2'500'000);  // one frame and a tail past the limit
    read_or_fail(f);
  }
  // Numbered on from the earlier run: the newest file carries the highest number.
  CHECK(files.back().filename().string() > files.front().filename().string());
}

TEST_CASE("MCAP configuration errors name the key and its place", "[daemon][mcap][config]") {
  test::ScratchDir dir("mcap-config");
  const auto topic =
      run_daemon(dir, "[output]\nmcap = true\nmcap_points_topic = \"points\"\n", "--check-config");
  CHECK(topic.exit_code == 78);
  CHECK(topic.out.find(":3:") != std::string::npos);
  CHECK(topic.out.find("must start with '/'") != std::string::npos);
  const auto frame =
      run_daemon(dir, "[output]\nmcap_frame_id = \"/base link\"\n", "--check-config");
  CHECK(frame.exit_code == 78);
  CHECK(frame.out.find("mcap_frame_id") != std::string::npos);
  const auto compression =
      run_daemon(dir, "[output]\nmcap_compression = \"brotli\"\n", "--check-config");
  CHECK(compression.exit_code == 78);
  CHECK(compression.out.find("lz4") != std::string::npos);
  const auto chunk = run_daemon(dir, "[output]\nmcap_chunk_bytes = 10\n", "--check-config");
  CHECK(chunk.exit_code == 78);
}

TEST_CASE("a full disk under MCAP: what was written is finished for the reader, losses counted",
          "[daemon][mcap][outputs][threads]") {
  if (test::run_command("command -v prlimit").exit_code != 0)
    FAIL("prlimit (util-linux) is needed");
  test::ScratchDir dir("mcap-full");
  const fs::path out = dir / "out";
  const fs::path config = dir / "pandarcap.toml";
  std::ofstream(config) << "[output]\nmcap = true\nframes = false\npcap = false\n"
                           "mcap_chunk_bytes = 65536\n";
  // Files may not grow past 3 MB: the MCAP file's write fails (EFBIG, as ENOSPC would) within the
  // first seconds.
  const auto r = test::run_command("prlimit --fsize=3000000 " + test::pandarcapd_command() +
                                   " -c " + quoted(config) + " --simulate --duration 3 " +
                                   "--output-dir " + quoted(out) + " 2>&1");
  INFO(r.out);
  REQUIRE(r.exit_code == 0);
  const json h = test::last_health_record(out);
  CHECK(test::health_counter(h, "mcap_messages_not_written") > 0);
  CHECK(test::health_counter(h, "write_errors") > 0);
  CHECK(test::files_ending(out / "mcap", ".part").empty());
  const auto files = test::files_ending(out / "mcap", ".mcap");
  REQUIRE_FALSE(files.empty());
  std::uint64_t messages = 0;
  for (const fs::path& f : files) {
    INFO(f.string());
    CHECK(fs::file_size(f) <= 3'000'000);
    const json file = read_or_fail(f);
    if (!file.is_null()) messages += file["statistics"]["message_count"].get<std::uint64_t>();
  }
  // Every message the exit summary counts as written is in a file the reader accepts.
  if (messages > 0) {
    CHECK(r.out.find(fmt::format("mcap: {} messages written, {} not written", messages,
                                 test::health_counter(h, "mcap_messages_not_written"))) !=
          std::string::npos);
  }
}

TEST_CASE("every compression setting gives files the reader accepts",
          "[daemon][mcap][realtime][threads]") {
  for (const std::string setting :
       {"mcap_compression = \"none\"", "mcap_compression = \"zstd\"\nmcap_compression_level = -7",
        "mcap_compression = \"zstd\"\nmcap_compression_level = 19",
        "mcap_compression_level = 1",  // the default compression: lz4
        "mcap_compression = \"lz4\"\nmcap_compression_level = 12"}) {
    test::ScratchDir dir("mcap-compression");
    const fs::path out = dir / "out";
    const auto r =
        run_daemon(dir, "[output]\nmcap = true\nframes = false\npcap = false\n" + setting + "\n",
                   "--simulate --duration 1 --output-dir " + quoted(out));
    INFO(setting << "\n" << r.out);
    REQUIRE(r.exit_code == 0);
    const auto files = test::files_ending(out / "mcap", ".mcap");
    REQUIRE(files.size() == 1);
    const json file = read_or_fail(files[0]);
    if (file.is_null()) continue;
    // Live, a compression slower than the sensor (zstd 19, lz4 12) leaves messages out, counted,
    // rather than hold the writer thread back: written or counted, every frame is there.
    const json h = test::last_health_record(out);
    // (A sanitizer build's simulator sends less than a second's packets in its second.)
    CHECK(file["topics"]["/pandar/points"]["count"].get<std::uint64_t>() +
              test::health_counter(h, "mcap_messages_not_recorded") >=
          (test::kSlowBuild ? 2u : 5u));
    const bool slow = setting.find("= 19") != std::string::npos ||
                      setting.find("level = 12") != std::string::npos;
    // The others keep up, but in a slow build (sanitizers, emulation), whose compressor can fall
    // a chunk behind on a busy machine as well (a TSan CI run left a frame's message out in
    // another test).
    if (!slow && !test::kSlowBuild) {
      CHECK(test::health_counter(h, "mcap_messages_not_recorded") == 0);
    }
    const char* expected = setting.find("none") != std::string::npos   ? ""
                           : setting.find("zstd") != std::string::npos ? "zstd"
                                                                       : "lz4";
    // A chunk taken while another waited behind it is stored as it is (compression ""), and
    // counted: the file has such chunks exactly when the count says so.
    const std::uint64_t stored = test::health_counter(h, "mcap_chunks_uncompressed");
    if (std::string(expected).empty()) {
      CHECK(stored == 0);  // nothing to fall back from
      CHECK(file["chunk_compression"] == json::array({""}));
    } else if (stored == 0) {
      CHECK(file["chunk_compression"] == json::array({expected}));
    } else {
      auto kinds = file["chunk_compression"].get<std::vector<std::string>>();
      std::ranges::sort(kinds);
      CHECK(kinds == std::vector<std::string>{"", expected});
    }
  }
}

TEST_CASE("live MCAP with a compressor slower than the sensor: chunks stored as they are",
          "[daemon][mcap][realtime][threads]") {
  // zstd at level 19 on 64 kB chunks of the simulated sensor's frames and packets: a chunk takes
  // it longer than the sensor takes to fill the next few, so the compression thread is soon a
  // chunk behind and stores chunks uncompressed, each counted.
  test::ScratchDir dir("mcap-behind");
  const fs::path out = dir / "out";
  const auto r = run_daemon(dir,
                            "[output]\nmcap = true\nmcap_packets = true\nframes = false\n"
                            "pcap = false\nmcap_compression = \"zstd\"\n"
                            "mcap_compression_level = 19\nmcap_chunk_bytes = 65536\n",
                            "--simulate --duration 2 --output-dir " + quoted(out));
  INFO(r.out);
  REQUIRE(r.exit_code == 0);
  const json h = test::last_health_record(out);
  INFO(h.dump());
  const std::uint64_t stored = test::health_counter(h, "mcap_chunks_uncompressed");
  CHECK(stored > 0);
  CHECK(r.out.find(fmt::format("; {} chunks stored uncompressed (compression behind)", stored)) !=
        std::string::npos);
  const auto files = test::files_ending(out / "mcap", ".mcap");
  REQUIRE(files.size() == 1);
  const json file = read_or_fail(files[0]);
  if (file.is_null()) return;
  // The reader's own view of every chunk: the stored ones are exactly those counted, the rest
  // zstd's, and the file reads whole (read_or_fail).
  const auto kinds = file["chunk_compressions"].get<std::vector<std::string>>();
  CHECK(static_cast<std::uint64_t>(std::ranges::count(kinds, "")) == stored);
  CHECK(static_cast<std::size_t>(std::ranges::count(kinds, "zstd")) + stored == kinds.size());
  // The final record counts the messages before its own.
  const std::uint64_t in_file = file["statistics"]["message_count"].get<std::uint64_t>();
  CHECK(in_file == test::health_counter(h, "mcap_messages_written") + 1);
  // Each packet accepted was offered as a message: written or counted as left out.
  CHECK(in_file + test::health_counter(h, "mcap_messages_not_recorded") >=
        test::health_counter(h, "packets_accepted"));
}

namespace {

// A field's value in a PCD row, as a number (what the reader prints).
double pcd_value(const std::string& data, std::size_t at, const PcdField& f) {
  const char* p = data.data() + at + f.offset;
  if (f.type == 'F') {
    if (f.size == 8) {
      double v;
      std::memcpy(&v, p, 8);
      return v;
    }
    float v;
    std::memcpy(&v, p, 4);
    return v;
  }
  std::uint64_t v = 0;
  std::memcpy(&v, p, f.size);  // little-endian
  return static_cast<double>(v);
}

}  // namespace

TEST_CASE("MCAP points are the PCD files' bytes in the layout and axes chosen and encoded once",
          "[daemon][mcap][realtime][threads]") {
  std::vector<std::pair<PcdLayout, const char*>> cases{{PcdLayout::kAutoware, "ros"},
                                                       {PcdLayout::kPcl, "hesai"}};
  // ThreadSanitizer runs the threads once, with the first layout: which bytes each layout holds
  // is the release and ASan jobs' question, and every point encoded costs TSan about 10 times.
  if (test::kThreadSanitizerBuild) cases.resize(1);
  for (const auto& [layout, frame] : cases) {
    INFO("layout " << to_string(layout) << ", sensor.frame " << frame);
    test::ScratchDir dir("mcap-layout");
    const fs::path out = dir / "out";
    const fs::path config = dir / "pandarcap.toml";
    std::ofstream(config) << "[sensor]\nframe = \"" << frame << "\"\n[output]\nmcap = true\n"
                          << "pcd_fields = \"" << to_string(layout) << "\"\n";
    const auto r =
        test::run_command(test::pandarcapd_command() + " -c " + quoted(config) +
                          " --simulate --duration 2 --output-dir " + quoted(out) + " 2>&1");
    INFO(r.out);
    REQUIRE(r.exit_code == 0);
    const auto files = test::files_ending(out / "mcap", ".mcap");
    REQUIRE(files.size() == 1);
    const json file = read_or_fail(files[0]);
    if (file.is_null()) continue;
    const json& messages = file["topics"]["/pandar/points"]["messages"];
    const auto pcds = test::files_ending(out / "frames", ".pcd");
    // None left out but in a slow build (pcds_of_messages).
    const std::uint64_t left_out =
        test::health_counter(test::last_health_record(out), "mcap_messages_not_recorded");
    if (!test::kSlowBuild) CHECK(left_out == 0);
    // Two seconds at 10 Hz; under ThreadSanitizer on a busy machine the decoder falls behind and
    // fewer frames are whole, and those left out are counted (each message there is still
    // compared byte for byte below).
    REQUIRE(messages.size() + left_out >= (test::kThreadSanitizerBuild ? 5u : 10u));
    REQUIRE(!messages.empty());
    const std::vector<fs::path> matched = pcds_of_messages(messages, pcds, left_out);
    const std::size_t step = pcd_point_bytes(layout);
    const auto fields = pcd_fields(layout);
    for (std::size_t i = 0; i < messages.size(); ++i) {
      INFO("frame " << i << ": " << matched[i].filename().string());
      const json& m = messages[i];
      const std::string pcd = harness::read_file(matched[i]);  // one read
      REQUIRE(m["point_step"] == step);
      REQUIRE(m["fields"].size() == fields.size());
      for (std::size_t k = 0; k < fields.size(); ++k) {
        CHECK(m["fields"][k]["name"] == fields[k].name);
        CHECK(m["fields"][k]["offset"] == fields[k].offset);
      }
      const std::size_t data_at = pcd.find("DATA binary\n");
      REQUIRE(data_at != std::string::npos);
      const std::string data = pcd.substr(data_at + 12);
      REQUIRE(m["points"] == data.size() / step);
      REQUIRE(data.size() % step == 0);
      if (data.empty()) continue;
      for (const PcdField& f : fields) {
        INFO("field " << f.name);
        CHECK(m["first"][std::string(f.name)].get<double>() == pcd_value(data, 0, f));
        CHECK(m["last"][std::string(f.name)].get<double>() ==
              pcd_value(data, data.size() - step, f));
      }
    }
  }
}
