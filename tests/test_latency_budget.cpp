// The latency budget ([latency] budget_ms): the receive thread sleeps up to the budget, drains the
// socket in full batches and wakes the decoder once per drain. Functional, not timed: what is
// checked is that nothing is lost or reordered, that the wake-up counts the daemon reports are
// bounded by the budget, that a burst is drained before the socket overflows, that SIGTERM still
// takes everything, and that budget 0 keeps the wake per datagram. The CPU it saves is measured
// in the benchmark (pandarcap-bench zero-loss), never here.
#include <fmt/format.h>

#include <catch2/catch.hpp>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "bench/child_process.hpp"
#include "bench/udp_traffic.hpp"
#include "core/sim/synthetic_sensor.hpp"
#include "daemon/pcap/capture_reader.hpp"
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

// A counter's rate over the records written while traffic flowed (the first and the last record
// whose datagram count moved), per second of the daemon's uptime.
double rate_while_receiving(const std::vector<json>& records, const std::string& name) {
  const json* first = nullptr;
  const json* last = nullptr;
  for (std::size_t i = 1; i < records.size(); ++i) {
    if (health_counter(records[i], "datagrams_received") >
        health_counter(records[i - 1], "datagrams_received")) {
      if (first == nullptr) first = &records[i - 1];
      last = &records[i];
    }
  }
  if (first == nullptr || last == first) return 0;
  const double seconds = (*last)["gauges"]["uptime_seconds"].get<double>() -
                         (*first)["gauges"]["uptime_seconds"].get<double>();
  return static_cast<double>(health_counter(*last, name) - health_counter(*first, name)) / seconds;
}

// The UDP sequence of every datagram the daemon recorded, in file order.
std::vector<std::uint32_t> recorded_sequences(const fs::path& out) {
  std::vector<std::uint32_t> sequences;
  for (const fs::path& pcap : test::files_ending(out / "raw", ".pcap")) {
    CaptureReader reader(pcap.string());
    CaptureRecord record;
    while (reader.next(record) == CaptureStatus::kRecord) {
      REQUIRE(record.payload.size() == 1266);
      std::uint32_t sequence = 0;
      for (int b = 3; b >= 0; --b)
        sequence = sequence << 8 | record.payload[1262 + static_cast<std::size_t>(b)];
      sequences.push_back(sequence);
    }
  }
  return sequences;
}

struct Run {
  json final_record;
  std::vector<json> records;
  std::uint64_t sent = 0;
  std::vector<std::uint32_t> recorded;
};

// The stream ends with 0.2 s at its base rate (LiveDaemon::send's tail), not faster.
Run paced_stream(const test::ScratchDir& dir, const std::string& extra,
                 const bench::GeneratorOptions& traffic) {
  LiveDaemon daemon(dir, extra);
  INFO(daemon.process->log());
  REQUIRE(daemon.ready());
  const bench::GeneratorResult sent = daemon.send(traffic, traffic.rate_pps);
  Run run;
  run.final_record = daemon.stop_after(sent.sent);
  INFO(daemon.process->log());
  REQUIRE(daemon.exit_status == 0);
  run.records = health_records(daemon.out);
  run.sent = sent.sent;
  run.recorded = recorded_sequences(daemon.out);
  return run;
}

}  // namespace

TEST_CASE(
    "latency budget: a paced stream arrives whole and in order, the decoder woken about "
    "once per budget - budget 0 wakes per datagram",
    "[daemon][latency][threads]") {
  bench::GeneratorOptions traffic;  // one dual-return sensor, 2 s
  traffic.rate_pps = 3600;
  traffic.seconds = 2;

  test::ScratchDir budget_dir("latency-budget-20");
  const Run budget = paced_stream(budget_dir, "[latency]\nbudget_ms = 20\n", traffic);
  test::ScratchDir zero_dir("latency-budget-0");
  const Run zero = paced_stream(zero_dir, "[latency]\nbudget_ms = 0\n", traffic);

  for (const Run* run : {&budget, &zero}) {
    const json& h = run->final_record;
    INFO(h.dump());
    const std::uint64_t overruns = test::check_ring_overruns(h);
    CHECK(health_counter(h, "packets_accepted") + overruns == run->sent);
    CHECK(health_counter(h, "kernel_drops") == 0);
    CHECK(health_counter(h, "sequence_lost") <= overruns);
    CHECK(health_counter(h, "sequence_reordered") == 0);
    CHECK(health_counter(h, "sequence_duplicates") == 0);
    // Sequence-exact: every datagram recorded once, in the order sent (sanitizer builds: or
    // counted as not recorded or overrun, and those recorded once each, in order; see
    // kSlowBuild).
    const std::uint64_t not_recorded =
        test::kSlowBuild ? health_counter(h, "pcap_packets_not_recorded") + overruns : 0;
    REQUIRE(run->recorded.size() + not_recorded == run->sent);
    for (std::size_t i = 0; i < run->recorded.size(); ++i) {
      const bool in_place = not_recorded == 0 ? run->recorded[i] == i
                                              : i == 0 || run->recorded[i] > run->recorded[i - 1];
      if (!in_place) FAIL("datagram " << i << " recorded as " << run->recorded[i]);
    }
    // Every frame written is measured from the packet that completed it.
    CHECK(h.at("frame_latency").at("count") > 0);
  }

  const double receive = rate_while_receiving(budget.records, "receive_wakeups");
  const double decode = rate_while_receiving(budget.records, "decode_wakeups");
  const double receive_0 = rate_while_receiving(zero.records, "receive_wakeups");
  const double decode_0 = rate_while_receiving(zero.records, "decode_wakeups");
  INFO("wake-ups per second, budget 20 ms: receive "
       << receive << ", decode " << decode << "; budget 0: receive " << receive_0 << ", decode "
       << decode_0);
  // 20 ms: 50 a second, plus the few short sleeps of the start; the decoder is woken once per
  // drain (and by its own 100 ms timeout at most 10 more).
  CHECK(receive > 0);
  CHECK(receive <= 1000.0 / 20 + 15);
  CHECK(decode <= 1000.0 / 20 + 25);
  // Budget 0: a wake-up per datagram, or nearly: 3600 a second are sent one by one (on a busy
  // machine a late wake takes several at once, so the bound is loose: 28 per wake on average).
  CHECK(receive_0 >= 2 * (1000.0 / 20 + 15));
  CHECK(receive_0 >= 3 * receive);
  // The JSON line's per-second gauges say the same as the counters.
  CHECK(budget.records.at(budget.records.size() / 2)["gauges"]["receive_wakeups_per_second"] <=
        1000.0 / 20 + 15);
}

TEST_CASE(
    "latency budget: a burst that would overflow the socket within the budget is drained "
    "early, without a kernel drop",
    "[daemon][latency][realtime][threads]") {
  test::ScratchDir dir("latency-burst");
  // The socket holds about 170 datagrams (200 000 bytes, doubled by the kernel, ~2.3 kB of
  // memory each). The budget is a second: a receiver that slept it whole would overflow during
  // every burst (400 a second for half a second: 200 datagrams). The daemon measures the fill at
  // each wake and sleeps about 100 ms at the base rate (1/8 full), so a burst leaves it ~300 ms
  // of slack: enough for a busy machine to run it late without a drop.
  bench::GeneratorOptions traffic;
  traffic.rate_pps = 200;
  traffic.seconds = 3;
  traffic.burst_factor = 2;
  traffic.burst_ms = 500;
  traffic.burst_every_s = 1;
  const Run run = paced_stream(
      dir, "udp_socket_receive_buffer_size_bytes = 200000\n[latency]\nbudget_ms = 1000\n", traffic);
  const json& h = run.final_record;
  INFO(h.dump());
  // Sanitizer builds: a drop is counted rather than absent (see kSlowBuild).
  const std::uint64_t kernel_drops = health_counter(h, "kernel_drops");
  const std::uint64_t not_recorded = health_counter(h, "pcap_packets_not_recorded");
  if (!test::kSlowBuild) {
    CHECK(kernel_drops == 0);
    CHECK(not_recorded == 0);
  }
  CHECK(health_counter(h, "packets_accepted") + kernel_drops == run.sent);
  CHECK(run.recorded.size() + not_recorded == health_counter(h, "packets_accepted"));
  // It woke more often than the budget alone would have it (once a second).
  const double receive = rate_while_receiving(run.records, "receive_wakeups");
  INFO("receive wake-ups per second: " << receive);
  CHECK(receive > 3);
}

TEST_CASE("latency budget: SIGTERM still takes everything the socket holds",
          "[daemon][latency][threads]") {
  test::ScratchDir dir("latency-sigterm");
  LiveDaemon daemon(dir, "[latency]\nbudget_ms = 100\n");
  INFO(daemon.process->log());
  REQUIRE(daemon.ready());
  // 150 datagrams at once, then SIGTERM straight away: they wait in the socket for the next
  // drain, which the stop must still do.
  SyntheticSensorConfig config;
  config.udp_sequence = true;
  SyntheticSensor sensor(config);
  std::vector<std::vector<std::uint8_t>> payloads;
  std::array<std::uint8_t, kMaxPacketBytes> packet{};
  for (int i = 0; i < 150; ++i) {
    const std::size_t size = sensor.next(packet);
    payloads.emplace_back(packet.begin(), packet.begin() + static_cast<long>(size));
  }
  harness::send_udp("127.0.0.1", daemon.port, payloads);
  const auto stopping = std::chrono::steady_clock::now();
  daemon.process->signal(SIGTERM);
  REQUIRE(daemon.process->wait_exit(10s) == 0);
  CHECK(std::chrono::steady_clock::now() - stopping < 2s);
  const auto records = health_records(daemon.out);
  REQUIRE_FALSE(records.empty());
  const json& h = records.back();
  INFO(h.dump());
  CHECK(health_counter(h, "packets_accepted") == 150);
  CHECK(health_counter(h, "kernel_drops") == 0);
  CHECK(recorded_sequences(daemon.out).size() == 150);
}

// A budget longer than the pipeline and the health allow is held to them (daemon_options.cpp
// longest_wait_ns): budget_ms = 1000 with no_data_timeout_seconds = 0.3 and a ring of seconds
// said no_data twice a second while the sensor sent, and dropped a frame in ten for want of an
// arena (a wake handed on ten frames to four arenas). A matrix of budgets, silences and the
// bound that holds (the silence, the arenas); each run is tried again, up to three times, if a
// busy machine stalls a thread past the silence (what this guards against fails every time).
TEST_CASE("latency budget: a long budget neither fakes a silence nor drops frames",
          "[daemon][latency][threads]") {
  struct Case {
    const char* name;
    std::uint32_t budget_ms;
    double no_data_s;
    double expected_ms;  // the wait the start says it shortened the budget to
  };
  // A ring of 65 536 slots and no pcap: only the arenas (4 x 360 packets of a 40P, a quarter of
  // them 100 ms) and the silence bound the wait.
  const Case cases[] = {{"1000 ms, silence 0.3 s", 1000, 0.3, 75.0},
                        {"300 ms, silence 0.2 s", 300, 0.2, 50.0},
                        {"1000 ms, silence 1 s (the arenas hold)", 1000, 1.0, 100.0}};
  for (const Case& c : cases) {
    DYNAMIC_SECTION(c.name) {
      bool whole = false;
      const int attempts = test::kSlowBuild ? 1 : 3;
      for (int attempt = 0; attempt < attempts && !whole; ++attempt) {
        CAPTURE(attempt);
        test::ScratchDir dir("latency-long-budget");
        const fs::path config = dir / "long.toml";
        std::ofstream(config) << "[ring]\nslots = 65536\n[output]\npcap = false\n[latency]\n"
                              << "budget_ms = " << c.budget_ms << "\n[health]\n"
                              << "no_data_timeout_seconds = " << c.no_data_s << "\n";
        const auto r = test::run_command(test::pandarcapd_command() + " -c " +
                                         test::quoted(config) + " --simulate --duration 2.5 " +
                                         "--output-dir " + test::quoted(dir / "out") + " 2>&1");
        INFO(r.out);
        REQUIRE(r.exit_code == 0);
        CHECK(r.out.find(fmt::format("latency.budget_ms {} shortened to {:.1f} ms", c.budget_ms,
                                     c.expected_ms)) != std::string::npos);
        const json last = test::last_health_record(dir / "out");
        INFO(last.dump());
        REQUIRE(health_counter(last, "datagrams_received") > 3000);
        // A sanitizer's threads may stall past a silence: the shortened wait is what is checked.
        if (test::kSlowBuild) break;
        whole = health_counter(last, "frames_dropped") == 0;
        bool flowing = false;
        for (const json& record : health_records(dir / "out")) {
          // Until the stop (the simulated sensor goes quiet first: a true silence).
          if (record.at("gauges").at("uptime_seconds").get<double>() > 2.2) break;
          if (flowing && record.at("state") == "no_data") {
            WARN("attempt " << attempt << ": no_data while the sensor sends: " << record.dump());
            whole = false;
          }
          flowing = flowing || health_counter(record, "datagrams_received") > 0;
        }
        if (!whole) WARN("attempt " << attempt << ": " << last.dump());
      }
      if (!test::kSlowBuild) CHECK(whole);
    }
  }
}
