// `pandarcap-bench zero-loss`: the highest packet rate the real pandarcapd takes with zero loss
// (RFC 2544 style binary search over trials of fixed length), next to two reference receivers
// searched the same way in the same run: a bare recvmmsg loop (the kernel path's ceiling on this
// machine) and a recvfrom loop (one packet per call, as the vendor SDKs receive). Plus trials at
// a dual-return sensor's rate (3600 packets/s) measuring the daemon's CPU per thread and per
// packet, with its latency budget and with budget 0, against the bare loop's CPU in the same
// run; its wake-ups per thread, frame and receive-to-decoded latency, peak RSS and hot-path
// allocations; and, if given, any other receiver's CPU, RSS and loss under the same traffic.
//
// Loss in a daemon trial is taken from the daemon's own final health record, per stage (kernel
// socket drops, ring overruns, rejects, frames dropped for want of an arena or by a busy writer,
// packets not recorded to pcap), and cross-checked against the generator's count: packets sent
// that the daemon never counted at all are reported as `unaccounted`.
#pragma once

#include <cstdint>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include "bench/udp_traffic.hpp"

namespace pandarcap::bench {

struct ZeroLossOptions {
  std::string daemon;            // pandarcapd to start; "" = the one beside pandarcap-bench
  std::string daemon_config;     // passed as -c; the harness overrides address, port and output
  std::string capture;           // packets to send; "" = the simulated sensor below
  SyntheticSensorConfig sensor;  // the simulated sensor: 600 RPM, dual return by default
  std::string work_dir;          // daemon outputs and logs; "" = a temporary directory, removed
  double trial_seconds = 10;     // RFC 2544 uses 60
  double min_rate = 1000;        // packets/s; the search starts by checking this rate
  double max_rate = 1'000'000;
  int steps = 7;  // bisections after the two end points (geometric)
  // Then trials between tested rates more than this factor apart, for the plot; 0 = none.
  double max_gap = 2;
  double sensor_rate = 3600;      // one dual-return Pandar40P at 600 RPM
  double loss_threshold = 0.005;  // the second search: highest rate at <= 0.5 % loss
  std::uint64_t receive_buffer_bytes = 8u << 20;  // reference receivers, as the daemon's default
  bool skip_references = false;                   // only the daemon (quick checks)
  bool sensor_rate_only = false;  // only the trials at the sensor's rate, no rate search
  // The daemon's latency.budget_ms in every trial; unset: its configured value (default 5).
  // The trials at the sensor's rate also run it with budget 0, for the comparison.
  std::optional<std::uint32_t> latency_budget_ms;
  // The rate search again with budget 0, for the comparison of zero-loss rates in one run.
  bool compare_budget_0 = false;
  // MCAP on vs off in one run: the sensor-rate trial and the zero-loss search again with
  // output.mcap (and output.mcap_packets) on, with the bytes each wrote, so the extra CPU can be
  // set against the extra bytes.
  bool compare_mcap = false;
  // The bare loop and the daemon at the sensor's rate, alternated this many times: the report's
  // daemon_vs_bare_cpu is the median round's (its trials give every other at_sensor_rate key),
  // each round's in at_sensor_rate.rounds. One trial of each on a shared VM varies by ~25 %.
  // Odd (the command line refuses an even count: two middle rounds).
  int sensor_rate_rounds = 3;
  // tcpdump -w beside the daemon at the sensor's rate, in this many trials (0 = none): the CPU
  // each takes to record the same packets in the same seconds, and their ratio
  // (`tcpdump_comparison`). Give the daemon `[output] frames = false` (--config) to compare
  // recording with recording.
  int tcpdump_rounds = 0;
  // Any other receiver, measured under the same traffic at the sensor's rate: started with
  // /bin/sh -c 'exec COMMAND', sent to 127.0.0.1:receiver_port; if it prints a line
  // "received N" (the last one counts), its loss is reported too.
  std::string receiver_command;
  std::uint16_t receiver_port = 0;
  // The daemon's receiver in every trial: "socket" (recvmmsg, the daemon's default) or
  // "packet_ring" (AF_PACKET TPACKET_V3 on `interface`, as root). With compare_receivers, the
  // sensor-rate trial (and its MCAP and tcpdump companions) runs with the other one too.
  std::string receiver = "socket";
  bool compare_receivers = false;
  // The path the packets take (bench/traffic_path.hpp): loopback by default; with `veth`, a veth
  // pair and a namespace the harness makes (root only); with `interface` alone, a real interface
  // the generator's packets to `destination` arrive on.
  bool veth = false;
  std::string interface;
  std::string destination;
  // Bursts and extra (foreign, malformed) traffic for every trial; destination, port, rate and
  // length are set per trial.
  GeneratorOptions traffic;
};

// The other receiver of the daemon's two ("socket" <-> "packet_ring").
std::string other_receiver(const std::string& receiver);

// Runs the whole measurement and returns the report. Throws std::runtime_error when the daemon
// cannot be started.
nlohmann::ordered_json run_zero_loss(const ZeroLossOptions& options);

// The Markdown summary of a report.
std::string zero_loss_markdown(const nlohmann::ordered_json& report);

// An SVG plot: offered vs delivered rate for the daemon and both reference receivers, and the
// daemon's loss per stage.
std::string zero_loss_svg(const nlohmann::ordered_json& report);

}  // namespace pandarcap::bench
