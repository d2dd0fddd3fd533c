// A datagram the decoder has no raw batch for (the writer held behind) is missing from every
// recording of packets, and each recording's count says so: the pcap's
// (pcap_packets_not_recorded) when it is on, the MCAP's (mcap_messages_not_recorded) when its
// files hold the packets, and neither when it is off. The real daemon, its simulated sensor, a
// writer held by the test hook (PANDARCAP_TEST_STALL_WRITER_FILE) and the files read back.
#include <fmt/format.h>
#include <signal.h>

#include <catch2/catch.hpp>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "bench/child_process.hpp"
#include "support/mcap_reader.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
using namespace std::chrono_literals;
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

struct HeldOutputs {
  const char* name;
  bool pcap;
  bool mcap_packets;
};

// The datagrams the MCAP file of `out` holds on its packets topic (nullopt: no reader here).
std::optional<std::uint64_t> mcap_packets_in_file(const fs::path& out) {
  const auto files = test::files_ending(out / "mcap", ".mcap");
  REQUIRE(files.size() == 1);
  const auto read = test::read_mcap_independently(files[0]);
  if (read.reader_missing) return std::nullopt;
  INFO(read.error);
  REQUIRE(read.file);
  const json& topics = (*read.file)["topics"];
  if (!topics.contains("/pandar/packets")) return 0;
  return topics["/pandar/packets"]["count"].get<std::uint64_t>();
}

// Waits `how_long` (the experiment's variable, not a wait for the daemon), requiring that the
// daemon does not exit meanwhile.
void keep_running(harness::ChildProcess& daemon, std::chrono::milliseconds how_long) {
  const auto from = std::chrono::steady_clock::now();
  while (std::chrono::steady_clock::now() - from < how_long)
    REQUIRE(daemon.wait_exit(100ms) == std::nullopt);
}

// The real daemon with its simulated sensor and `config` (TOML), writing to `out`, started with
// the writer-stall hook at `stall`; once it has written 4 frames its writer is held (until
// `stall` is removed) for 2 s: the raw batches (4 x 512 datagrams, 0.57 s of the simulated
// sensor) run out, the decoder's wait for one ends within a second, and from then on datagrams
// are not recorded.
std::unique_ptr<harness::ChildProcess> held_daemon(const test::ScratchDir& dir,
                                                   const std::string& config, const fs::path& out,
                                                   const fs::path& stall) {
  const fs::path config_file = dir / "held.toml";
  std::ofstream(config_file) << config;
  auto daemon = std::make_unique<harness::ChildProcess>(
      test::binary("pandarcapd"),
      std::vector<std::string>{"--allow-root", "-c", config_file.string(), "--simulate",
                               "--output-dir", out.string()},
      dir / "log.txt",
      std::vector<std::string>{"PANDARCAP_TEST_STALL_WRITER_FILE=" + stall.string()});
  REQUIRE(harness::wait_until(
      [&] { return test::health_counter(test::last_health_record(out), "frames_written") >= 4; },
      20s));
  REQUIRE(test::stall_writer(*daemon, stall, 10s));
  keep_running(*daemon, 2s);
  return daemon;
}

}  // namespace

TEST_CASE("a held writer: each datagram left out is counted by every recording of packets",
          "[daemon][mcap][reliability][threads]") {
  const HeldOutputs outputs = GENERATE(HeldOutputs{"pcap and MCAP packets", true, true},
                                       HeldOutputs{"MCAP packets, no pcap", false, true},
                                       HeldOutputs{"pcap, MCAP without packets", true, false});
  INFO(outputs.name);
  test::ScratchDir dir("packets-not-recorded");
  const fs::path out = dir / "out";
  const fs::path stall = dir / "stall-writer";
  const auto held = held_daemon(dir,
                                fmt::format("[output]\npcap = {}\nmcap = true\nmcap_packets = {}\n",
                                            outputs.pcap, outputs.mcap_packets),
                                out, stall);
  harness::ChildProcess& daemon = *held;
  fs::remove(stall);
  // What the decoder left out reaches the health once the writer is back.
  const char* counted_in =
      outputs.pcap ? "pcap_packets_not_recorded" : "mcap_messages_not_recorded";
  REQUIRE(harness::wait_until(
      [&] { return test::health_counter(test::last_health_record(out), counted_in) > 0; }, 15s));
  daemon.signal(SIGTERM);
  INFO(daemon.log());
  REQUIRE(daemon.wait_exit(15s) == 0);

  const json h = test::last_health_record(out);
  INFO(h.dump());
  const auto c = [&](const char* name) { return test::health_counter(h, name); };
  // Every datagram past the ring goes to the raw batches, or is counted as having none.
  const std::uint64_t offered = c("datagrams_received") - test::check_ring_overruns(h);
  if (outputs.pcap) {
    CHECK(c("pcap_packets_not_recorded") > 0);
    CHECK(c("pcap_packets_written") + c("pcap_packets_not_recorded") == offered);
    CHECK(c("packets_not_recorded") == c("pcap_packets_not_recorded"));
  } else {
    // No pcap: nothing is left out of one, whatever the decoder had no batch for.
    CHECK(c("pcap_packets_not_recorded") == 0);
    CHECK(c("packets_not_recorded") == 0);
  }
  const std::uint64_t mcap_left_out = c("mcap_messages_not_recorded");
  if (outputs.mcap_packets) {
    CHECK(mcap_left_out > 0);
    // The MCAP left out at least what the pcap did (the same datagrams had no batch), and
    // every datagram is in the file or counted (the chunk buffers may have left out more).
    if (outputs.pcap) CHECK(mcap_left_out >= c("pcap_packets_not_recorded"));
    const auto in_file = mcap_packets_in_file(out);
    if (in_file) CHECK(*in_file + mcap_left_out >= offered);
    // Said, not only counted: a record while it happened names the MCAP's loss.
    bool said = false;
    for (const json& record : test::health_records(out))
      said = said ||
             record.value("reason", "").find("MCAP messages not recorded") != std::string::npos;
    CHECK(said);
  } else {
    // Frames and health only: the datagrams' loss is not the MCAP's (a frame or two the chunk
    // buffers left out after the hold at most, never the thousands of datagrams; a slow build's
    // compression may leave out more frames, each still one message).
    CHECK(mcap_left_out < c("pcap_packets_not_recorded"));
    if (!test::kSlowBuild) CHECK(mcap_left_out <= 4);
  }
  // The exit summary's MCAP line, the same count.
  CHECK_THAT(daemon.log(),
             Catch::Contains(fmt::format("not written, {} not recorded, ", mcap_left_out)));
}

namespace {

// What the health's reasons said, over every record of `out`, of a loss `what` (" packets not
// recorded"): the sum of each "N<what>" (a record's reason names its second's count).
std::uint64_t said_in_reasons(const fs::path& out, const std::string& what) {
  std::uint64_t said = 0;
  for (const json& record : test::health_records(out)) {
    const std::string reason = record.value("reason", "");
    for (auto at = reason.find(what); at != std::string::npos; at = reason.find(what, at + 1)) {
      std::size_t digits = at;
      while (digits > 0 && reason[digits - 1] >= '0' && reason[digits - 1] <= '9')
        --digits;
      if (digits < at) said += std::stoull(reason.substr(digits, at - digits));
    }
  }
  return said;
}

}  // namespace

TEST_CASE("a stop while the writer is held: the last seconds' losses are said, not only counted",
          "[daemon][mcap][reliability][threads]") {
  // SIGTERM stops the receiver while the writer is held: the writer, released later, counts
  // what it could not keep. Every datagram left out of the pcap and of the MCAP is in a
  // record's reason, and the records after the stop do not call the sensor silent: the daemon
  // stopped listening, the sensor did not stop sending.
  test::ScratchDir dir("packets-not-recorded-stop");
  const fs::path out = dir / "out";
  const fs::path stall = dir / "stall-writer";
  const auto held = held_daemon(dir, "[output]\nmcap = true\nmcap_packets = true\n", out, stall);
  harness::ChildProcess& daemon = *held;
  daemon.signal(SIGTERM);
  // Held on past the no-data timeout (1 s): the writer's last record comes more than a second
  // after the last packet, which it once took for a silent sensor (no_data).
  keep_running(daemon, 1500ms);  // the writer is still held
  fs::remove(stall);
  INFO(daemon.log());
  REQUIRE(daemon.wait_exit(15s) == 0);

  const json h = test::last_health_record(out);
  INFO(h.dump());
  const std::uint64_t pcap_left_out = test::health_counter(h, "pcap_packets_not_recorded");
  const std::uint64_t mcap_left_out = test::health_counter(h, "mcap_messages_not_recorded");
  CHECK(pcap_left_out > 0);
  CHECK(mcap_left_out >= pcap_left_out);
  CHECK(said_in_reasons(out, " packets not recorded") == pcap_left_out);
  CHECK(said_in_reasons(out, " MCAP messages not recorded") == mcap_left_out);
  // The sensor sent until the stop: the last record says what was lost, and no silence.
  CHECK(h.value("state", "") == "degraded");
  CHECK(h.at("gauges").value("seconds_since_last_packet", 9.0) < 0.5);
  for (const json& record : test::health_records(out)) {
    INFO(record.dump());
    CHECK(record.value("state", "") != "no_data");
  }
}
