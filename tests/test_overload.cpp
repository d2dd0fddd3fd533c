// pandarcapd overloaded and attacked, on real loopback sockets: every datagram the generator sent
// ends up counted somewhere, exactly.
//
//   - Overload: sequenced packets in bursts far beyond what a small socket buffer holds. After
//     shutdown, sent = kernel drops + rejects + ring overruns + accepted; the sequence tracker's
//     loss is exactly the packets that never reached the decoder; the per-second health records
//     add up to the final totals.
//   - Hostile flood: random-length random datagrams from the sensor's address and copies of the
//     stream from 127.0.0.2, at the highest rate loopback takes, mixed into the valid stream: no
//     crash, rejects and foreign datagrams counted, the valid stream's loss fully accounted for.
#include <signal.h>

#include <catch2/catch.hpp>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "bench/child_process.hpp"
#include "bench/udp_traffic.hpp"
#include "support/live_daemon.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
using namespace std::chrono_literals;
using nlohmann::json;
namespace fs = std::filesystem;
using test::health_counter;
using test::health_records;
using test::LiveDaemon;

namespace {

// The counters the identities below use.
const std::vector<std::string> kCounters = {
    "datagrams_received", "kernel_drops",      "ring_overruns",       "packets_accepted",
    "packets_rejected",   "foreign_datagrams", "sequence_lost",       "sequence_gaps",
    "frames_complete",    "frames_written",    "pcap_packets_written"};

// The per-second records: never a counter going down, about a second apart (the final record
// may follow the last one sooner), and the first record plus each second's increase is the
// final total.
void check_per_second_records(const std::vector<json>& records, const json& final_record) {
  REQUIRE(records.size() >= 3);
  for (const std::string& name : kCounters) {
    std::uint64_t total = health_counter(records.front(), name);
    for (std::size_t i = 1; i < records.size(); ++i) {
      const std::uint64_t before = health_counter(records[i - 1], name);
      const std::uint64_t now = health_counter(records[i], name);
      INFO(name << " in record " << i);
      CHECK(now >= before);
      total += now - before;
    }
    INFO(name);
    CHECK(total == health_counter(final_record, name));
  }
  test::check_record_spacing(records, 0.0);
}

}  // namespace

TEST_CASE(
    "overload: sent = kernel drops + rejects + ring overruns + accepted, gaps agree, "
    "per-second records add up",
    "[daemon][reliability][overload][realtime][threads]") {
  test::ScratchDir dir("daemon-overload");
  // A socket buffer of a few dozen datagrams and the smallest ring: bursts must overflow.
  LiveDaemon daemon(dir,
                    "udp_socket_receive_buffer_size_bytes = 65536\n[ring]\nslots = 64\n"
                    "receive_batch = 32\n");
  INFO(daemon.process->log());
  REQUIRE(daemon.ready());

  bench::GeneratorOptions traffic;
  traffic.rate_pps = 10000;
  traffic.seconds = 3.5;
  // 30 ms at 50x the rate at the start of every second: 15,000 packets in a burst-second.
  traffic.burst_factor = 50;
  traffic.burst_ms = 30;
  traffic.burst_every_s = 1;
  const bench::GeneratorResult sent = daemon.send(traffic);
  const json final_record = daemon.stop_after(sent.sent);
  INFO(daemon.process->log());
  INFO(final_record.dump());
  CHECK(daemon.exit_status == 0);

  const std::uint64_t kernel = health_counter(final_record, "kernel_drops");
  const std::uint64_t overruns = health_counter(final_record, "ring_overruns");
  const std::uint64_t rejected = health_counter(final_record, "packets_rejected");
  const std::uint64_t accepted = health_counter(final_record, "packets_accepted");
  INFO("sent " << sent.sent << ": " << kernel << " kernel drops, " << overruns << " ring overruns, "
               << rejected << " rejected, " << accepted << " accepted");
  REQUIRE(kernel + overruns > 0);  // it was an overload
  CHECK(sent.sent == kernel + rejected + overruns + accepted);
  CHECK(health_counter(final_record, "datagrams_received") == accepted + rejected + overruns);
  CHECK(rejected == 0);
  // The sequence numbers agree: what is missing from the stream is what was dropped before the
  // decoder.
  CHECK(health_counter(final_record, "sequence_lost") == kernel + overruns);
  CHECK(health_counter(final_record, "sequence_gaps") >= 1);
  CHECK(health_counter(final_record, "sequence_gaps") <=
        health_counter(final_record, "sequence_lost"));
  // Every packet that reached the decoder was recorded, unless counted as not recorded.
  CHECK(health_counter(final_record, "pcap_packets_written") +
            health_counter(final_record, "pcap_packets_not_recorded") ==
        accepted + rejected);
  check_per_second_records(health_records(daemon.out), final_record);
  // The Prometheus file holds the same final totals.
  const std::string prom = harness::read_file(daemon.out / "health" / "pandarcap.prom");
  CHECK(prom.find("pandarcap_kernel_drops_total{sensor=\"pandar40p\"} " + std::to_string(kernel) +
                  "\n") != std::string::npos);
  CHECK(prom.find("pandarcap_packets_accepted_total{sensor=\"pandar40p\"} " +
                  std::to_string(accepted) + "\n") != std::string::npos);
}

TEST_CASE(
    "hostile flood: random datagrams and a foreign sender at loopback's top rate, mixed "
    "with the stream: no crash, everything counted",
    "[daemon][reliability][overload][threads]") {
  test::ScratchDir dir("daemon-flood");
  LiveDaemon daemon(dir, "");
  INFO(daemon.process->log());
  REQUIRE(daemon.ready());

  bench::GeneratorOptions traffic;
  traffic.rate_pps = 40000;
  traffic.seconds = 3;
  traffic.foreign_fraction = 1;    // as many copies from 127.0.0.2 ...
  traffic.malformed_fraction = 4;  // ... and four times as many random datagrams
  traffic.burst_factor = 10;       // with bursts at 10x: the flood peaks past 2M datagrams/s
  traffic.burst_ms = 50;
  const bench::GeneratorResult sent = daemon.send(traffic);
  const std::uint64_t total = sent.sent + sent.foreign_sent + sent.malformed_sent;
  const json final_record = daemon.stop_after(total);
  INFO(daemon.process->log());
  INFO(final_record.dump());
  CHECK(daemon.exit_status == 0);  // no crash: a clean exit on SIGTERM

  const std::uint64_t kernel = health_counter(final_record, "kernel_drops");
  const std::uint64_t overruns = health_counter(final_record, "ring_overruns");
  const std::uint64_t rejected = health_counter(final_record, "packets_rejected");
  const std::uint64_t foreign = health_counter(final_record, "foreign_datagrams");
  const std::uint64_t accepted = health_counter(final_record, "packets_accepted");
  INFO("sent " << sent.sent << " valid, " << sent.foreign_sent << " foreign, "
               << sent.malformed_sent << " random: " << kernel << " kernel drops, " << overruns
               << " ring overruns, " << rejected << " rejected, " << foreign << " foreign, "
               << accepted << " accepted");
  // Every datagram sent is received or counted as dropped by the kernel, and every received one
  // is accepted, rejected, foreign or overrun.
  CHECK(total == health_counter(final_record, "datagrams_received") + kernel);
  CHECK(health_counter(final_record, "datagrams_received") ==
        accepted + rejected + foreign + overruns);
  CHECK(rejected > 0);
  CHECK(foreign > 0);
  // Only the random datagrams are rejected, at most all of them.
  CHECK(rejected <= sent.malformed_sent);
  CHECK(foreign <= sent.foreign_sent);
  // The valid stream: every packet accepted or lost, and the loss is what the sequence numbers
  // say (drops fall on all three kinds of traffic, so the stream's share is only bounded).
  CHECK(accepted + health_counter(final_record, "sequence_lost") == sent.sent);
  CHECK(health_counter(final_record, "sequence_lost") <= kernel + overruns);
  // The randoms are counted by reason; none of them decoded into a frame of garbage.
  std::uint64_t by_reason = 0;
  for (const auto& [reason, n] : final_record["counters"]["rejects"].items())
    by_reason += n.get<std::uint64_t>();
  CHECK(by_reason == rejected);
  check_per_second_records(health_records(daemon.out), final_record);
}
