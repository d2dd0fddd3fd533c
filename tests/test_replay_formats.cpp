// A replay, whatever the capture holds: IPv4 or IPv6, pcap or pcapng, recorded on any day. The
// sensor's clock is judged against the capture's own record times (never the day the replay
// runs on), IPv6/UDP datagrams are decoded like IPv4 ones and recorded again as IPv6, and what
// the replay cannot use (IP fragments, other protocols) is counted where the user looks: the
// exit summary, a warning, and pandarcap-inspect's summary.
#include <fmt/format.h>

#include <atomic>
#include <catch2/catch.hpp>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>

#include "bench/child_process.hpp"
#include "core/sim/synthetic_sensor.hpp"
#include "daemon/pcap/capture_reader.hpp"
#include "daemon/pcap/pcap_writer.hpp"
#include "daemon/source/replay_source.hpp"
#include "support/capture_bytes.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
using namespace std::chrono_literals;
using nlohmann::json;
namespace fs = std::filesystem;
using test::health_counter;

namespace {

// 2023-03-01T08:00:00Z: a recording from an earlier day than any the tests run on.
constexpr std::int64_t kReplayRecordedNs = 1'677'657'600'000'000'000;
constexpr int kReplayPackets = 7200;  // two seconds of a dual-return sensor at 600 RPM
constexpr Endpoint kReplayLidar{0xC0A801C9, 2368};
constexpr Endpoint kReplayHost{0xC0A8010A, 2368};
constexpr Endpoint kReplayLidar6{
    0, 2368, true, {0xFD, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 2, 1}};
constexpr Endpoint kReplayHost6{
    0, 2368, true, {0xFD, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0x10}};

fs::path write_replay_recording(const fs::path& path, Endpoint from, Endpoint to) {
  return test::write_simulated_recording(path, kReplayPackets, kReplayRecordedNs, from, to);
}

// The same records in pcapng (nanosecond times), from a classic pcap PcapWriter wrote.
fs::path to_pcapng(const fs::path& pcap, const fs::path& path) {
  const std::string bytes = harness::read_file(pcap);
  test::Bytes out = test::pcapng_header();
  for (std::size_t at = kPcapGlobalHeaderBytes; at + kPcapRecordHeaderBytes <= bytes.size();) {
    std::uint32_t header[4];
    std::memcpy(header, bytes.data() + at, sizeof header);  // seconds, us, captured, original
    const auto* frame = reinterpret_cast<const std::uint8_t*>(bytes.data()) + at + 16;
    const std::uint64_t ns = std::uint64_t{header[0]} * 1'000'000'000 + header[1] * 1000ull;
    test::append(out, test::pcapng_packet(test::Bytes(frame, frame + header[2]), ns));
    at += kPcapRecordHeaderBytes + header[2];
  }
  std::ofstream(path, std::ios::binary)
      .write(reinterpret_cast<const char*>(out.data()), static_cast<std::streamsize>(out.size()));
  return path;
}

struct Replayed {
  test::CommandResult run;
  json health;
};

Replayed replay(const fs::path& capture, const fs::path& out) {
  Replayed r;
  r.run = test::run_command(test::pandarcapd_command() + " --replay '" + capture.string() +
                            "' --output-dir '" + out.string() + "' 2>&1");
  r.health = test::last_health_record(out);
  return r;
}

}  // namespace

TEST_CASE("a replay is judged by its capture's clock: an earlier day's recording is not degraded",
          "[daemon][replay][threads]") {
  test::ScratchDir dir("replay-formats");
  const fs::path v4 = write_replay_recording(dir / "v4.pcap", kReplayLidar, kReplayHost);
  const fs::path v6 = write_replay_recording(dir / "v6.pcap", kReplayLidar6, kReplayHost6);
  const fs::path v6ng = to_pcapng(v6, dir / "v6.pcapng");
  std::uint64_t frames_v4 = 0;
  for (const fs::path& capture : {v4, v6, v6ng}) {
    const fs::path out = dir / ("out-" + capture.filename().string());
    const Replayed r = replay(capture, out);
    INFO(capture.filename() << ":\n" << r.run.out << "\n" << r.health.dump());
    REQUIRE(r.run.exit_code == 0);
    // The sensor's clock agrees with the record times (300 us apart), years before today.
    const json& gauges = r.health.at("gauges");
    REQUIRE(gauges.contains("sensor_clock_offset_seconds"));
    CHECK(std::abs(gauges.at("sensor_clock_offset_seconds").get<double>()) < 1.0);
    CHECK(r.health.at("reason").get<std::string>().find("clock") == std::string::npos);
    CHECK(r.run.out.find("clock off") == std::string::npos);
    // Every packet decoded, whatever the network layer.
    CHECK(health_counter(r.health, "datagrams_received") == kReplayPackets);
    CHECK(health_counter(r.health, "packets_accepted") == kReplayPackets);
    const std::uint64_t frames = health_counter(r.health, "frames_complete");
    CHECK(frames >= 18);
    if (capture == v4) frames_v4 = frames;
    CHECK(frames == frames_v4);  // IPv6 decodes to the same frames as IPv4
    const bool ipv6 = capture != v4;
    CHECK(r.run.out.find(fmt::format("{} UDP datagrams ({} IPv6)", kReplayPackets,
                                     ipv6 ? kReplayPackets : 0)) != std::string::npos);
    CHECK(r.run.out.find("0 skipped") != std::string::npos);
    // Recorded again as it came: IPv6 datagrams with IPv6 headers, the same payloads.
    const auto recordings = test::files_ending(out / "raw", ".pcap");
    REQUIRE(recordings.size() == 1);
    CaptureReader reader(recordings.front().string());
    CaptureRecord record;
    std::uint64_t read = 0;
    while (reader.next(record) == CaptureStatus::kRecord) {
      if (read == 0) CHECK(record.source == (ipv6 ? kReplayLidar6 : kReplayLidar));
      ++read;
    }
    CHECK(read == kReplayPackets);
    CHECK(reader.stats().ipv6_datagrams == (ipv6 ? kReplayPackets : 0));
  }
}

TEST_CASE("what a replay skips is never silent: the summary, a warning and pandarcap-inspect",
          "[daemon][replay][threads]") {
  test::ScratchDir dir("replay-skipped");
  const fs::path capture =
      write_replay_recording(dir / "fragments.pcap", kReplayLidar, kReplayHost);
  // Three records become IPv4 fragments (more-fragments set), one a TCP segment.
  std::string bytes = harness::read_file(capture);
  const std::size_t record_bytes = kPcapRecordOverheadBytes + kMaxPacketBytes - 4;  // 1262 B
  const auto ip_header = [&](int i) {
    return kPcapGlobalHeaderBytes + static_cast<std::size_t>(i) * record_bytes +
           kPcapRecordHeaderBytes + 14;
  };
  for (int i : {100, 101, 102})
    bytes[ip_header(i) + 6] |= 0x20;
  bytes[ip_header(200) + 9] = 6;
  std::ofstream(capture, std::ios::binary | std::ios::trunc) << bytes;

  const Replayed r = replay(capture, dir / "out");
  INFO(r.run.out);
  REQUIRE(r.run.exit_code == 0);
  CHECK(health_counter(r.health, "datagrams_received") == kReplayPackets - 4);
  CHECK(r.run.out.find("4 skipped (0 not IP, 1 not UDP, 3 IP fragments, 0 malformed)") !=
        std::string::npos);
  CHECK(r.run.out.find("4 of 7200 records skipped") != std::string::npos);  // the warning

  const auto inspect =
      test::run_command(test::binary("pandarcap-inspect").string() + " '" + capture.string() + "'");
  INFO(inspect.out);
  CHECK(inspect.exit_code == 0);
  CHECK(inspect.out.find("skipped 4 (not IP 0, not UDP 1, IP fragments 3, malformed 0)") !=
        std::string::npos);
  const auto inspect_json = test::run_command(test::binary("pandarcap-inspect").string() +
                                              " --json '" + capture.string() + "'");
  const json summary = json::parse(inspect_json.out, nullptr, false);
  REQUIRE_FALSE(summary.is_discarded());
  CHECK(summary["summary"]["capture"]["skipped"] == 4);
  CHECK(summary["summary"]["capture"]["ip_fragments"] == 3);
  CHECK(summary["summary"]["packets"] == kReplayPackets - 4);
}

// A replay never overruns its ring: it waits for the decoder to free a slot. A stop during that
// wait leaves the record it holds unsent, and then it must not be counted as received either:
// it was in datagrams_received and in no count after it (accepted, rejected, recorded), one
// datagram short in every identity of a replay stopped while its decoder or writer was behind.
TEST_CASE("a replay stopped while it waits for a ring slot counts only what it put in the ring",
          "[daemon][replay][threads]") {
  test::ScratchDir dir("replay-stop-full-ring");
  const fs::path capture = write_replay_recording(dir / "v4.pcap", kReplayLidar, kReplayHost);
  ReplayOptions options;
  options.path = capture.string();  // top speed
  ReplaySource source(options);
  constexpr std::size_t kSlots = 256;  // nobody takes them: the replay fills them, then waits
  PacketRing ring(kSlots);
  std::atomic<bool> stop{false};
  ReceiveCounters counters;
  std::atomic<std::uint64_t> heartbeat{0};
  ReplayResult result;
  std::thread replay([&] { result = source.run(ring, stop, counters, heartbeat); });
  const bool full = harness::wait_until([&] { return ring.size_approx() == kSlots; }, 10s);
  stop.store(true);
  replay.join();
  REQUIRE(full);
  CHECK(result.stopped);
  // Counted: what is in the ring. Read: that, and the record that waited for a slot, if the
  // stop came after the replay had read it (as it nearly always has: it reads on at once).
  CHECK(counters.datagrams.load() == kSlots);
  CHECK(counters.bytes.load() == kSlots * 1262u);
  CHECK(result.capture.records - kSlots <= 1);
  CHECK(counters.foreign.load() == 0);
}
