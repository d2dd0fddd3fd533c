// Nothing lost, nothing overwritten, bounded disk: pandarcapd's outputs across restarts, hostile
// senders, cut datagrams, shared directories and failing writes. The real binaries on real files
// and loopback sockets; every wait is a condition with a deadline.
//
// Each case is a regression test for a failure found by hostile testing of an earlier version:
// a restart within the same second (or a sensor clock restarting at the same value) renamed new
// files over finished ones; retention counted only the current run's files; a stream of
// discontinuities turned each packet into a PCD file; a datagram cut by the socket or by a
// capture's snap length was recorded as whole; two daemons shared one directory; crash recovery
// followed a symbolic link out of raw/; an unwritable frames/ was found only after READY; and the
// exit summary repeated a stale health line when the last one could not be written.
#include <fmt/format.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <catch2/catch.hpp>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <nlohmann/json.hpp>
#include <random>
#include <set>
#include <string>
#include <tuple>
#include <vector>

#include "bench/child_process.hpp"
#include "core/sim/packet_builder.hpp"
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
using test::quoted;

namespace {

std::string pandarcapd() {
  return test::pandarcapd_command();
}

json last_health(const fs::path& out) {
  return test::last_health_record(out);
}

// A pcap of `packets` simulated dual-return packets (with UDP sequence), recorded at the sensor's
// own packet times: every replay of it gives frames and recordings the same times, as a sensor
// whose clock restarts at the same value does.
fs::path sensor_capture(const fs::path& path, int packets) {
  SyntheticSensorConfig config;
  config.udp_sequence = true;
  SyntheticSensor sensor(config);
  std::array<std::uint8_t, kMaxPacketBytes> packet{};
  PcapWriter pcap(path.string());
  for (int i = 0; i < packets; ++i) {
    const std::size_t size = sensor.next(packet);
    pcap.write({packet.data(), size}, sensor.last_packet_time_ns(), Endpoint{0xC0A801C9, 2368},
               Endpoint{0xC0A80164, 2368});
  }
  pcap.close();
  return path;
}

// The names of an output directory's frames and recordings (what retention counts).
std::set<std::string> output_names(const fs::path& out) {
  std::set<std::string> names;
  for (const fs::path& f : files_ending(out / "frames", ".pcd"))
    names.insert("frames/" + f.filename().string());
  for (const fs::path& f : files_ending(out / "raw", ".pcap"))
    names.insert("raw/" + f.filename().string());
  return names;
}

// Every frame and recording of an output directory, by name, with its bytes.
std::map<std::string, std::string> outputs(const fs::path& out) {
  std::map<std::string, std::string> files;
  for (const fs::path& f : files_ending(out / "frames", ".pcd"))
    files["frames/" + f.filename().string()] = harness::read_file(f);
  for (const fs::path& f : files_ending(out / "raw", ".pcap"))
    files["raw/" + f.filename().string()] = harness::read_file(f);
  return files;
}

// What was there before is still there, byte for byte.
void check_kept(const std::map<std::string, std::string>& before,
                const std::map<std::string, std::string>& now) {
  for (const auto& [name, bytes] : before) {
    INFO(name);
    REQUIRE(now.count(name) == 1);
    CHECK(now.at(name) == bytes);
  }
}

std::size_t count_prefix(const std::map<std::string, std::string>& files, const std::string& p) {
  std::size_t n = 0;
  for (const auto& entry : files)
    n += entry.first.rfind(p, 0) == 0;
  return n;
}

std::size_t occurrences(const std::string& text, const std::string& what) {
  std::size_t n = 0;
  for (std::size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1))
    ++n;
  return n;
}

}  // namespace

TEST_CASE("restarts within one second never replace a finished frame or recording",
          "[daemon][outputs][threads]") {
  test::ScratchDir dir("outputs-restart");
  const fs::path out = dir / "out";
  const fs::path capture = sensor_capture(dir / "sensor.pcap", 1200);

  SECTION("replays of one capture: the same sensor times every run") {
    std::map<std::string, std::string> before;
    std::size_t frames = 0;
    for (int run = 1; run <= 3; ++run) {
      const auto r = test::run_command(pandarcapd() + " --replay " + quoted(capture) +
                                       " --output-dir " + quoted(out) + " 2>&1");
      INFO("run " << run << ": " << r.out);
      REQUIRE(r.exit_code == 0);
      const json h = last_health(out);
      CHECK(health_counter(h, "frames_written") >= 3);
      CHECK(health_counter(h, "output_name_collisions") == 0);
      frames += health_counter(h, "frames_written");
      const auto now = outputs(out);
      check_kept(before, now);
      CHECK(count_prefix(now, "frames/") == frames);
      CHECK(count_prefix(now, "raw/") == static_cast<std::size_t>(run));
      before = now;
    }
  }
  SECTION("simulated runs started back to back (a crash loop, systemctl restart)") {
    std::map<std::string, std::string> before;
    const auto started = std::chrono::steady_clock::now();
    for (int run = 1; run <= 3; ++run) {
      const auto r = test::run_command(pandarcapd() + " --simulate --duration 0.3 --output-dir " +
                                       quoted(out) + " 2>&1");
      INFO("run " << run << ": " << r.out);
      REQUIRE(r.exit_code == 0);
      const auto now = outputs(out);
      check_kept(before, now);
      CHECK(count_prefix(now, "raw/") == static_cast<std::size_t>(run));
      CHECK(health_counter(last_health(out), "output_name_collisions") == 0);
      before = now;
    }
    // The condition the names used to collide under (informative: on a loaded machine the runs
    // may straddle more seconds, which the test does not need).
    INFO("three runs took "
         << std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count()
         << " s");
    CHECK(files_ending(out / "raw", ".pcap").size() == 3);
  }
}

TEST_CASE(
    "retention and rotation allocate nothing once warm: a frame in, the oldest out, a recording "
    "rotated, the oldest out",
    "[daemon][outputs][threads]") {
  // Sanitizer builds keep their own allocator: there the daemon counts nothing.
  if (test::kSanitizerBuild) return;
  test::ScratchDir dir("outputs-retention-allocations");
  const fs::path out = dir / "out";
  const fs::path config = dir / "retention.toml";
  // 5 frames kept of ~50 written: from the first second on, every frame in removes one. The
  // recordings (~2.3 MB/s) rotate every 256 KiB, several times a second, and 2 are kept: each
  // rotation after the warm-up opens a file and removes the oldest with its sidecars.
  // MCAP too, in 256 KiB chunks and files, 2 kept: each chunk closes a file (its size read, its
  // name logged on SIGHUP) and retention removes one.
  std::ofstream(config) << "[output]\nframes_max_files = 5\npcap_max_files = 2\n"
                           "pcap_rotate_bytes = 262144\nmcap = true\nmcap_packets = true\n"
                           "mcap_chunk_bytes = 262144\nmcap_rotate_bytes = 262144\n"
                           "mcap_max_files = 2\n";
  const auto r = test::run_command(pandarcapd() + " -c " + quoted(config) + " --output-dir " +
                                   quoted(out) + " --simulate --duration 5 2>&1");
  INFO(r.out);
  REQUIRE(r.exit_code == 0);
  const json h = last_health(out);
  INFO(h.dump());
  CHECK(health_counter(h, "frames_written") >= 30);
  CHECK(files_ending(out / "frames", ".pcd").size() == 5);
  // Rotation and retention really happened (many files written, 2 kept): ~11 MB in 256 KiB files.
  CHECK(health_counter(h, "pcap_bytes_written") >= 8 * 262144);
  CHECK(files_ending(out / "raw", ".pcap").size() == 2);
  CHECK(files_ending(out / "mcap", ".mcap").size() == 2);
  CHECK(health_counter(h, "mcap_bytes_written") >= 4 * 262144);
  CHECK(h.at("counters").at("write_errors") == 0);
  for (const char* thread : {"receive", "decode", "writer"}) {
    INFO(thread);
    CHECK(h.at("counters").at("hot_path_allocations_by_thread").at(thread) == 0);
  }
}

TEST_CASE("retention counts the frames and recordings of earlier runs",
          "[daemon][outputs][threads]") {
  test::ScratchDir dir("outputs-retention");
  const fs::path out = dir / "out";
  const fs::path capture = sensor_capture(dir / "sensor.pcap", 2400);  // ~6.7 revolutions
  const fs::path retention = dir / "retention.toml";
  std::ofstream(retention) << "[output]\ndirectory = \"" << out.string()
                           << "\"\nframes_max_files = 5\npcap_max_files = 2\n";
  const fs::path unlimited = dir / "unlimited.toml";
  std::ofstream(unlimited) << "[output]\ndirectory = \"" << out.string() << "\"\n";
  // Files that are not ours are never counted or removed.
  fs::create_directories(out / "raw");
  fs::create_directories(out / "frames");
  std::ofstream(out / "raw" / "notes.txt") << "operator's notes\n";
  std::ofstream(out / "frames" / "frame_reference.pcd") << "not one of ours\n";
  const auto replay = [&](const fs::path& config) {
    const auto r = test::run_command(pandarcapd() + " -c " + quoted(config) + " --replay " +
                                     quoted(capture) + " 2>&1");
    INFO(r.out);
    REQUIRE(r.exit_code == 0);
    CHECK(health_counter(last_health(out), "frames_written") >= 5);
    return r.out;
  };
  // Ours, without the two foreign files. Names only: reading every file's bytes each time took
  // most of this test's time under TSan (35 s), where it checks names alone.
  const auto ours = [&](const std::string& kind) {
    std::set<std::string> names;
    for (const std::string& name : output_names(out)) {
      if (name.rfind(kind, 0) == 0 && name != "frames/frame_reference.pcd") names.insert(name);
    }
    return names;
  };

  SECTION("three runs with retention leave what it allows, not three times that") {
    std::set<std::string> last_two_pcaps;
    for (int run = 1; run <= 3; ++run) {
      const auto before = ours("");
      const std::string log = replay(retention);
      if (run > 1) CHECK(log.find("of earlier runs") != std::string::npos);
      CHECK(ours("frames/").size() == 5);
      const auto pcaps = ours("raw/");
      CHECK(pcaps.size() == static_cast<std::size_t>(std::min(run, 2)));
      if (run >= 2) {
        for (const std::string& p : pcaps)
          if (before.count(p) == 0) last_two_pcaps.insert(p);
      }
      // The survivors are the newest: this run wrote at least 5 frames, so they are all its own.
      for (const std::string& frame : ours("frames/")) {
        INFO(frame);
        CHECK(before.count(frame) == 0);
      }
    }
    CHECK(ours("raw/") == last_two_pcaps);
  }
  SECTION("files left by runs without retention are trimmed when a run with it starts") {
    replay(unlimited);
    replay(unlimited);
    const std::size_t frames_before = ours("frames/").size();
    CHECK(frames_before >= 10);
    CHECK(ours("raw/").size() == 2);
    const auto before = ours("");
    const std::string log = replay(retention);
    CHECK(log.find("retention removed the oldest " + std::to_string(frames_before - 5)) !=
          std::string::npos);
    CHECK(ours("frames/").size() == 5);
    CHECK(ours("raw/").size() == 2);
    for (const std::string& frame : ours("frames/"))
      CHECK(before.count(frame) == 0);
  }
  CHECK(fs::exists(out / "raw" / "notes.txt"));
  CHECK(fs::exists(out / "frames" / "frame_reference.pcd"));
}

TEST_CASE("a recovered recording whose name is taken is kept beside it, never over it",
          "[daemon][outputs][threads]") {
  test::ScratchDir dir("outputs-recovered");
  const fs::path out = dir / "out";
  const fs::path capture = sensor_capture(dir / "sensor.pcap", 300);
  const std::string replay =
      pandarcapd() + " --replay " + quoted(capture) + " --output-dir " + quoted(out) + " 2>&1";
  REQUIRE(test::run_command(replay).exit_code == 0);
  const auto first = files_ending(out / "raw", ".pcap");
  REQUIRE(first.size() == 1);
  const std::string finished = harness::read_file(first[0]);
  // A killed run's .part under the finished file's name, cut inside its last record.
  const fs::path part = first[0].string() + ".part";
  std::ofstream(part, std::ios::binary) << finished << std::string(7, '\x5A');

  const auto r = test::run_command(replay);
  INFO(r.out);
  REQUIRE(r.exit_code == 0);
  CHECK(harness::read_file(first[0]) == finished);  // untouched
  const fs::path dup = fs::path(first[0]).replace_filename(first[0].stem().string() + "_dup1.pcap");
  REQUIRE(fs::exists(dup));
  CHECK(harness::read_file(dup) == finished);  // recovered: cut back to its whole records
  CHECK(health_counter(last_health(out), "output_name_collisions") == 1);
  CHECK(r.out.find("instead of replacing it") != std::string::npos);
  CHECK(files_ending(out / "raw", ".pcap").size() == 3);  // first, its recovered twin, this run's
  CHECK(files_ending(out / "raw", ".part").empty());
}

TEST_CASE("a stream of discontinuities cannot turn packets into files",
          "[daemon][outputs][threads]") {
  test::ScratchDir dir("outputs-fragments");
  // Valid-looking packets in runs of 18 at random azimuths: each run follows on in itself (17
  // that do, and it is no glitch but a change, see core/decode/stream_decoder.hpp), and each is a
  // discontinuity from the last.
  const fs::path capture = dir / "hostile.pcap";
  {
    SyntheticSensor sensor(SyntheticSensorConfig{});
    std::mt19937 rng(17);
    std::array<std::uint8_t, kMaxPacketBytes> packet{};
    PcapWriter pcap(capture.string());
    std::uint16_t base = 0;
    for (int i = 0; i < 3000; ++i) {
      PacketContents contents = sensor.next_contents();
      // Dual return at 600 RPM: a packet takes 1°, and so the next in a run starts 1° on; the
      // next run starts more than 90° away (a discontinuity to the frame assembler).
      base =
          static_cast<std::uint16_t>((base + (i % 18 == 0 ? 9100 + rng() % 17800 : 100)) % 36000);
      for (int b = 0; b < kBlocks; ++b)
        contents.azimuth_cdeg[b] = static_cast<std::uint16_t>((base + b / 2 * 20) % 36000);
      const std::size_t size = encode(contents, packet);
      pcap.write({packet.data(), size}, sensor.last_packet_time_ns(), Endpoint{0xC0A801C9, 2368},
                 Endpoint{0xC0A80164, 2368});
    }
    pcap.close();
  }
  const auto run = [&](const std::string& extra, const fs::path& out) {
    const auto r = test::run_command(pandarcapd() + extra + " --replay " + quoted(capture) +
                                     " --output-dir " + quoted(out) + " 2>&1");
    INFO(r.out);
    REQUIRE(r.exit_code == 0);
    return std::make_pair(last_health(out), r.out);
  };

  const auto [h, log] = run("", dir / "out");
  INFO(h.dump());
  CHECK(health_counter(h, "packets_accepted") == 3000);
  CHECK(health_counter(h, "frames_fragment") >= 150);  // 166 runs, each cut apart
  CHECK(health_counter(h, "frames_written") <= 5);
  CHECK(health_counter(h, "frames_written") + health_counter(h, "frames_fragment") ==
        health_counter(h, "frames_complete") + health_counter(h, "frames_partial"));
  CHECK(files_ending(dir / "out" / "frames", ".pcd").size() == health_counter(h, "frames_written"));
  // Rate-limited: a line at most every 10 s, not one per fragment.
  CHECK(occurrences(log, "frame fragment") <= 2);

  // The knob: 0 writes every frame, slivers included (what the earlier version always did).
  const fs::path config = dir / "all.toml";
  std::ofstream(config) << "[output]\nframes_min_fraction = 0.0\n";
  const auto [all, all_log] = run(" -c " + quoted(config), dir / "all");
  CHECK(health_counter(all, "frames_fragment") == 0);
  CHECK(health_counter(all, "frames_written") >= 150);
}

TEST_CASE("a datagram the socket cut is recorded with its true length, not as whole",
          "[daemon][outputs][threads]") {
  test::ScratchDir dir("outputs-cut-live");
  const fs::path out = dir / "out";
  const std::uint16_t port = harness::free_udp_port();
  harness::ChildProcess daemon(test::binary("pandarcapd"),
                               {"--allow-root", "--host-ip", "127.0.0.1", "--port",
                                std::to_string(port), "--output-dir", out.string()},
                               dir / "log.txt");
  REQUIRE(
      harness::wait_until([&] { return daemon.log().find("ready") != std::string::npos; }, 10s));
  SyntheticSensor sensor(SyntheticSensorConfig{});
  std::array<std::uint8_t, kMaxPacketBytes> packet{};
  const std::size_t size = sensor.next(packet);
  const std::vector<std::vector<std::uint8_t>> sent = {
      std::vector<std::uint8_t>(1281, 0xA1), std::vector<std::uint8_t>(65507, 0xB2),
      std::vector<std::uint8_t>(packet.begin(), packet.begin() + static_cast<long>(size))};
  harness::send_udp("127.0.0.1", port, sent);
  REQUIRE(harness::wait_until(
      [&] { return health_counter(last_health(out), "datagrams_received") == 3; }, 10s));
  daemon.signal(SIGTERM);
  INFO(daemon.log());
  REQUIRE(daemon.wait_exit(10s) == 0);
  const json h = last_health(out);
  CHECK(health_counter(h, "truncated_datagrams") == 2);
  CHECK(health_counter(h, "packets_accepted") == 1);
  CHECK(health_counter(h, "pcap_packets_written") == 3);  // every datagram, the cut ones as cut

  const auto pcaps = files_ending(out / "raw", ".pcap");
  REQUIRE(pcaps.size() == 1);
  CaptureReader reader(pcaps[0].string());
  CaptureRecord record;
  std::vector<std::tuple<std::size_t, std::uint32_t, bool>> records;  // kept, UDP length, snapped
  while (reader.next(record) == CaptureStatus::kRecord) {
    records.emplace_back(record.payload.size(), record.udp_payload_length, record.snapped);
    if (records.size() <= 2) {  // the bytes kept are the datagram's first bytes
      CHECK(std::all_of(record.payload.begin(), record.payload.end(),
                        [&](std::uint8_t b) { return b == sent[records.size() - 1][0]; }));
    }
  }
  REQUIRE(records.size() == 3);
  CHECK(records[0] == std::make_tuple(std::size_t{1280}, 1281u, true));
  CHECK(records[1] == std::make_tuple(std::size_t{1280}, 65507u, true));
  CHECK(records[2] == std::make_tuple(size, static_cast<std::uint32_t>(size), false));
  // tcpdump sees the lengths the wire had.
  const auto dump = test::run_command("tcpdump -nr " + quoted(pcaps[0]) + " 2>/dev/null");
  CHECK(dump.out.find("length 1281") != std::string::npos);
  CHECK(dump.out.find("length 65507") != std::string::npos);
  // And inspect rejects the recording's cut datagrams exactly as the daemon did.
  const auto inspect = test::run_command(test::binary("pandarcap-inspect").string() +
                                         " --json --summary " + quoted(pcaps[0]));
  REQUIRE(inspect.exit_code == 0);
  const json s = json::parse(inspect.out).at("summary");
  CHECK(s.at("accepted") == 1);
  CHECK(s.at("rejects").at("bad_length") == 2);
}

TEST_CASE("a replayed record cut by the snap length stays cut in the recording and in inspect",
          "[daemon][outputs][threads]") {
  test::ScratchDir dir("outputs-cut-replay");
  const fs::path capture = sensor_capture(dir / "snapped.pcap", 3);
  // The second record keeps 1262 of its 1266 payload bytes (snaplen); its headers still say 1266.
  std::string bytes = harness::read_file(capture);
  const std::size_t second = 24 + 16 + 42 + 1266;
  const std::uint32_t kept = 42 + 1262;
  std::memcpy(&bytes[second + 8], &kept, 4);  // incl_len (native order, as written)
  bytes.erase(second + 16 + kept, 4);
  std::ofstream(capture, std::ios::binary | std::ios::trunc) << bytes;

  const auto inspect =
      test::run_command(test::binary("pandarcap-inspect").string() + " --json " + quoted(capture));
  REQUIRE(inspect.exit_code == 0);
  const json j = json::parse(inspect.out);
  CHECK(j.at("summary").at("accepted") == 2);
  CHECK(j.at("summary").at("rejects").at("bad_length") == 1);
  CHECK(j.at("packets").at(1).at("status") == "bad_length");
  CHECK(j.at("packets").at(1).at("original_size") == 1266);

  const fs::path out = dir / "out";
  const auto run = test::run_command(pandarcapd() + " --replay " + quoted(capture) +
                                     " --output-dir " + quoted(out) + " 2>&1");
  INFO(run.out);
  REQUIRE(run.exit_code == 0);
  const json h = last_health(out);
  CHECK(health_counter(h, "packets_accepted") == 2);
  CHECK(h["counters"]["rejects"].value("bad_length", 0) == 1);
  const auto pcaps = files_ending(out / "raw", ".pcap");
  REQUIRE(pcaps.size() == 1);
  CaptureReader reader(pcaps[0].string());
  CaptureRecord record;
  std::vector<std::pair<std::size_t, bool>> records;
  while (reader.next(record) == CaptureStatus::kRecord)
    records.emplace_back(record.payload.size(), record.snapped);
  CHECK(records ==
        std::vector<std::pair<std::size_t, bool>>{{1266, false}, {1262, true}, {1266, false}});
}

TEST_CASE("two daemons on one output directory: the second refuses with exit 73",
          "[daemon][outputs][threads]") {
  test::ScratchDir dir("outputs-lock");
  const fs::path out = dir / "out";
  auto first = std::make_unique<harness::ChildProcess>(
      test::binary("pandarcapd"),
      std::vector<std::string>{"--allow-root", "--simulate", "--output-dir", out.string()},
      dir / "first.txt");
  REQUIRE(
      harness::wait_until([&] { return first->log().find("ready:") != std::string::npos; }, 10s));
  REQUIRE(harness::wait_until([&] { return files_ending(out / "raw", ".pcap.part").size() == 1; },
                              10s));
  const auto open_part = files_ending(out / "raw", ".pcap.part");

  const auto second = test::run_command(pandarcapd() + " --simulate --duration 1 --output-dir " +
                                        quoted(out) + " 2>&1");
  INFO(second.out);
  CHECK(second.exit_code == 73);
  CHECK(second.out.find("another pandarcapd (pid " + std::to_string(first->pid()) + ")") !=
        std::string::npos);
  // The first one's open recording was not "recovered" from under it.
  CHECK(files_ending(out / "raw", ".pcap.part") == open_part);
  CHECK(first->wait_exit(0ms) == std::nullopt);

  // A killed holder leaves no stale lock: the kernel drops it with the process.
  first->signal(SIGKILL);
  CHECK(first->wait_exit(10s).has_value());
  first.reset();
  const auto third = test::run_command(pandarcapd() + " --simulate --duration 0.5 --output-dir " +
                                       quoted(out) + " 2>&1");
  INFO(third.out);
  CHECK(third.exit_code == 0);
}

TEST_CASE("crash recovery never follows a symbolic link out of raw/",
          "[daemon][outputs][threads]") {
  test::ScratchDir dir("outputs-symlink");
  const fs::path out = dir / "out";
  // Elsewhere: a recording that recovery would cut (it ends inside a record).
  const fs::path victim = dir / "elsewhere.pcap";
  sensor_capture(victim, 5);
  std::ofstream(victim, std::ios::binary | std::ios::app) << "cut";
  const std::string before = harness::read_file(victim);
  fs::create_directories(out / "raw");
  const fs::path link = out / "raw" / "pandarcap_20260101T000000Z_0000.pcap.part";
  fs::create_symlink(victim, link);

  const fs::path capture = sensor_capture(dir / "sensor.pcap", 50);
  const auto r = test::run_command(pandarcapd() + " --replay " + quoted(capture) +
                                   " --output-dir " + quoted(out) + " 2>&1");
  INFO(r.out);
  REQUIRE(r.exit_code == 0);
  CHECK(harness::read_file(victim) == before);
  CHECK(fs::is_symlink(link));
  CHECK(r.out.find("not a regular file; left as it is") != std::string::npos);
}

TEST_CASE("pandarcapd --check-config refuses exactly what the start refuses",
          "[daemon][outputs][threads]") {
  test::ScratchDir dir("outputs-check-config");
  const auto both = [&](const std::string& toml) {
    const fs::path config = dir / "c.toml";
    std::ofstream(config, std::ios::trunc) << toml;
    const auto check =
        test::run_command(pandarcapd() + " --check-config -c " + quoted(config) + " 2>&1");
    const auto start = test::run_command(pandarcapd() + " -c " + quoted(config) +
                                         " --simulate --duration 0.5 2>&1");
    INFO(toml << "\n--check-config: " << check.out << "\nstart: " << start.out);
    CHECK(check.exit_code == start.exit_code);
    return check;
  };
  const std::string out = "[output]\ndirectory = \"" + (dir / "out").string() + "\"\n";

  const auto missing =
      both(out + "[sensor]\ncalibration_file = \"" + (dir / "missing.csv").string() + "\"\n");
  CHECK(missing.exit_code == 78);
  CHECK(missing.out.find("missing.csv") != std::string::npos);

  std::ofstream(dir / "bad.csv") << "Laser id,Elevation,Azimuth\n1,+-1,0\n";
  const auto bad =
      both(out + "[sensor]\ncalibration_file = \"" + (dir / "bad.csv").string() + "\"\n");
  CHECK(bad.exit_code == 78);
  CHECK(bad.out.find("bad.csv:2:") != std::string::npos);

  std::ofstream(dir / "a-file") << "x";
  const auto not_a_directory =
      both("[output]\ndirectory = \"" + (dir / "a-file" / "out").string() + "\"\n");
  CHECK(not_a_directory.exit_code == 73);
  CHECK(not_a_directory.out.find("is not a directory") != std::string::npos);

  const auto prom =
      both(out + "[health]\nprometheus_file = \"" + (dir / "a-file").string() + "/x.prom\"\n");
  CHECK(prom.exit_code == 73);
  CHECK(prom.out.find("textfile directory") != std::string::npos);

  const auto good = both(out);
  CHECK(good.exit_code == 0);
}

TEST_CASE("an unwritable frames/ is refused before READY, and by --check-config",
          "[daemon][outputs][threads]") {
  test::ScratchDir dir("outputs-frames-readonly");
  const fs::path out = dir / "out";
  fs::create_directories(out / "frames");
  // As root (CI) the daemon runs as nobody, for whom frames/ (root's, 0755) is read-only; as an
  // ordinary user, frames/ is made read-only for that user.
  std::string as_user;
  if (::geteuid() == 0) {
    fs::permissions(dir.path(), fs::perms::all);  // nobody may reach and create out/'s entries
    fs::permissions(out, fs::perms::all);
    as_user = "setpriv --reuid=65534 --regid=65534 --clear-groups -- ";
  } else {
    fs::permissions(out / "frames", fs::perms::owner_read | fs::perms::owner_exec);
  }
  const std::string daemon = as_user + pandarcapd() + " --output-dir " + quoted(out);
  const auto check = test::run_command(daemon + " --check-config 2>&1");
  INFO(check.out);
  CHECK(check.exit_code == 73);
  CHECK(check.out.find("frames directory") != std::string::npos);
  const auto start = test::run_command(daemon + " --simulate --duration 1 2>&1");
  INFO(start.out);
  CHECK(start.exit_code == 73);
  CHECK(start.out.find("frames") != std::string::npos);
  CHECK(start.out.find("ready:") == std::string::npos);
  fs::permissions(out / "frames", fs::perms::all);  // so the scratch directory can go
}

TEST_CASE("the exit summary is the run's real end, even when health.jsonl could not take it",
          "[daemon][outputs][threads]") {
  if (test::run_command("command -v prlimit").exit_code != 0) {
    FAIL("prlimit (util-linux) is needed");
  }
  test::ScratchDir dir("outputs-summary");
  const fs::path out = dir / "out";
  fs::create_directories(out / "health");
  // health.jsonl a few bytes short of the file-size limit the daemon runs under: its first
  // health line fails (EFBIG), as on a full disk, and the file's last line stays an old one.
  constexpr std::size_t kLimit = 256 * 1024;
  {
    std::ofstream jsonl(out / "health" / "health.jsonl");
    for (std::size_t written = 0; written + 3 < kLimit - 64; written += 3)
      jsonl << "{}\n";
  }
  const auto r =
      test::run_command("prlimit --fsize=" + std::to_string(kLimit) + " " + pandarcapd() +
                        " --simulate --duration 2 --output-dir " + quoted(out) + " 2>&1");
  INFO(r.out);
  REQUIRE(r.exit_code == 0);  // EFBIG counted, not a SIGXFSZ death
  CHECK(r.out.find("final health: state degraded") != std::string::npos);
  CHECK(r.out.find("File too large") != std::string::npos);
  const auto records = test::json_lines(out / "health" / "health.jsonl");
  REQUIRE_FALSE(records.empty());
  CHECK(health_counter(records.back(), "datagrams_received") == 0);  // the stale line
}

TEST_CASE("a health line an interrupted run cut short is removed at start, the lines before kept",
          "[daemon][outputs][threads]") {
  test::ScratchDir dir("outputs-health-cut");
  const fs::path out = dir / "out";
  fs::create_directories(out / "health");
  const std::string whole = R"({"earlier":"run","counters":{"datagrams_received":7}})";
  const std::string cut = R"({"counters":{"datagrams_rec)";  // a kill mid-append
  std::ofstream(out / "health" / "health.jsonl") << whole << "\n" << cut;
  const auto r = test::run_command(pandarcapd() + " --simulate --duration 2 --output-dir " +
                                   quoted(out) + " 2>&1");
  INFO(r.out);
  REQUIRE(r.exit_code == 0);
  CHECK(r.out.find(fmt::format("a line cut short by an interrupted run removed ({} bytes)",
                               cut.size())) != std::string::npos);
  std::ifstream in(out / "health" / "health.jsonl", std::ios::binary);
  const std::string text{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  CHECK(text.starts_with(whole + "\n{"));  // the new run's first line right after the kept one
  CHECK(text.ends_with("\n"));
  const auto records = test::json_lines(out / "health" / "health.jsonl");
  REQUIRE(records.size() >= 3);  // the earlier line, a line a second, the final line
  CHECK(records.front()["earlier"] == "run");
  CHECK(health_counter(records.back(), "datagrams_received") > 0);
}

TEST_CASE("a run with another calibration keeps the earlier recordings' table beside them",
          "[daemon][outputs][threads]") {
  test::ScratchDir dir("outputs-calibration");
  const fs::path out = dir / "out";
  const fs::path capture = sensor_capture(dir / "sensor.pcap", 100);
  const auto nominal = test::run_command(pandarcapd() + " --print-calibration");
  REQUIRE(nominal.exit_code == 0);
  // Another unit's table: channel 1's elevation (15 degrees nominal) is 14.9.
  std::string other = nominal.out;
  const std::size_t elevation = other.find("\n1,") + 3;
  REQUIRE(elevation != std::string::npos + 3);
  other.replace(elevation, other.find(',', elevation) - elevation, "14.9");
  std::ofstream(dir / "other.csv") << other;
  const auto replay = [&](const std::string& calibration) {
    const auto r = test::run_command(pandarcapd() + calibration + " --replay " + quoted(capture) +
                                     " --output-dir " + quoted(out) + " 2>&1");
    INFO(r.out);
    REQUIRE(r.exit_code == 0);
  };
  replay("");
  CHECK(harness::read_file(out / "raw" / "calibration.csv") == nominal.out);
  replay(" --calibration " + quoted(dir / "other.csv"));
  CHECK(harness::read_file(out / "raw" / "calibration.csv") != nominal.out);
  // Recording 0000 was made with the nominal table, 0001 with the other one.
  CHECK(harness::read_file(out / "raw" / "calibration_before_0001.csv") == nominal.out);
  replay(" --calibration " + quoted(dir / "other.csv"));  // the same again: nothing new kept
  std::size_t tables = 0;
  for (const fs::path& csv : files_ending(out / "raw", ".csv"))
    if (!csv.filename().string().starts_with("pandarcap_")) ++tables;
  CHECK(tables == 2);
  // Each recording carries the table it was made with beside it, whatever came later.
  const std::vector<fs::path> recordings = files_ending(out / "raw", ".pcap");
  REQUIRE(recordings.size() == 3);
  for (std::size_t i = 0; i < recordings.size(); ++i) {
    const std::string stem = recordings[i].string().substr(0, recordings[i].string().size() - 5);
    INFO(stem);
    CHECK(harness::read_file(stem + ".calibration.csv") ==
          (i == 0 ? nominal.out : harness::read_file(dir / "other.csv")));
    // The sensor facts of that run (the last run's are raw/sensor.json too).
    const std::string facts = harness::read_file(stem + ".sensor.json");
    CHECK(facts.find(i == 0 ? "\"calibration_source\": \"nominal\"" : "other.csv") !=
          std::string::npos);
    if (i + 1 == recordings.size()) CHECK(facts == harness::read_file(out / "raw" / "sensor.json"));
  }
}

TEST_CASE("with output.upload, the recordings the upload moved are not counted lost",
          "[daemon][outputs][upload][threads]") {
  test::ScratchDir dir("outputs-upload-moved");
  const fs::path out = dir / "out";
  const fs::path remote = dir / "remote";  // where the upload put them (rclone move)
  fs::create_directories(remote);
  std::ofstream(dir / "up.toml") << "[output]\npcap_rotate_seconds = 1\nmcap = true\n"
                                    "mcap_rotate_seconds = 1\nupload = true\n";
  harness::ChildProcess daemon(test::binary("pandarcapd"),
                               {"--allow-root", "-c", (dir / "up.toml").string(), "--simulate",
                                "--output-dir", out.string()},
                               dir / "log.txt");
  // Moved as the upload moves them: finished files only, never a .part.
  std::size_t moved = 0;
  REQUIRE(harness::wait_until(
      [&] {
        for (const char* sub : {"raw", "mcap"}) {
          for (const char* suffix : {".pcap", ".mcap"}) {
            for (const fs::path& f : files_ending(out / sub, suffix)) {
              std::error_code ec;
              fs::rename(f, remote / f.filename(), ec);
              if (!ec) ++moved;
            }
          }
        }
        return moved >= 4;
      },
      20s));
  daemon.signal(SIGTERM);
  INFO(daemon.log());
  REQUIRE(daemon.wait_exit(30s) == 0);
  const json last = test::last_health_record(out);
  INFO(last.dump());
  // They left for the upload: not lost, nothing said as lost, the log says where they went.
  CHECK(health_counter(last, "pcap_packets_lost") == 0);
  CHECK(health_counter(last, "mcap_messages_lost") == 0);
  // Nothing failed to be written; a slow build's writer may fall behind and leave packets out
  // of the recording (counted as not recorded, not as lost).
  CHECK(health_counter(last, "packets_not_recorded") ==
        (test::kSlowBuild ? health_counter(last, "pcap_packets_not_recorded") : 0));
  // Every datagram received is written or counted as not recorded (or, under TSan, overrun).
  CHECK(health_counter(last, "pcap_packets_written") +
            health_counter(last, "pcap_packets_not_recorded") + test::check_ring_overruns(last) ==
        health_counter(last, "datagrams_received"));
  CHECK(last.at("reason").get<std::string>().find("lost") == std::string::npos);
  CHECK(daemon.log().find("have left") != std::string::npos);
  CHECK(daemon.log().find("not counted as recorded") == std::string::npos);
}
