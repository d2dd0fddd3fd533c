// The trials of `pandarcap-bench zero-loss`: one measured run of a receiver under paced loopback
// traffic. The real pandarcapd (its loss per stage from its own final health record, its CPU per
// thread, wake-ups, latency, peak RSS and bytes written), the reference receivers (a bare
// recvmmsg loop and a recvfrom loop, in this process), or any other receiver a command starts.
// The search (zero_loss_search.hpp) decides which rates to try; zero_loss.cpp assembles the
// report.
#pragma once

#include <cstdint>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "bench/traffic_path.hpp"
#include "bench/udp_traffic.hpp"
#include "bench/zero_loss.hpp"

namespace pandarcap::bench {

// a / b, 0 when b is 0.
double ratio(double a, std::uint64_t b);

// `s` without its trailing newlines and spaces.
std::string trim(std::string s);

class ZeroLossTrials {
 public:
  // `work`: where each daemon trial's outputs and log go (emptied after the trial, removed with
  // this object). `path`: where the generator sends, where the receivers listen. Throws
  // std::runtime_error when the options ask for the packet_ring receiver and the daemon has no
  // --receiver option.
  ZeroLossTrials(const ZeroLossOptions& options, const TrafficSource& source,
                 std::filesystem::path work, TrafficPath path);
  // Removes the trials' outputs.
  ~ZeroLossTrials();
  ZeroLossTrials(const ZeroLossTrials&) = delete;
  ZeroLossTrials& operator=(const ZeroLossTrials&) = delete;

  // The pandarcapd the trials start.
  const std::filesystem::path& daemon() const { return daemon_; }
  // The receive buffer the daemon said it was granted, from its first trial's log.
  std::string daemon_socket_buffer;

  // One trial of the real daemon at `rate`; its outputs are emptied afterwards (a fast trial
  // writes gigabytes of pcap), each file cut to 0 bytes but kept until the run ends: ext4 without
  // a journal makes every file created near inodes freed in the last minutes dear (it reads past
  // each; 1 ms a file measured in a /tmp after many removals), so removing one trial's thousand
  // files would charge the next trial's daemon for them (docs/performance.md). With
  // `beside_tcpdump`, `tcpdump -i IFACE -w FILE udp dst port P` records the same packets in the
  // same seconds (key "tcpdump": its CPU, what it captured and dropped, its file's bytes), for the
  // comparison of what recording costs. `receiver`: the daemon's ("" = the options'), with
  // --interface the path's when it is packet_ring.
  nlohmann::ordered_json daemon_trial(double rate, double seconds,
                                      std::optional<std::uint32_t> budget_ms = std::nullopt,
                                      const std::vector<std::string>& extra_args = {},
                                      bool beside_tcpdump = false,
                                      const std::string& receiver = "");

  // Any receiver the user names, under the same traffic: its CPU (all threads), peak RSS and,
  // when it prints "received N", its loss.
  nlohmann::ordered_json other_receiver_trial(double rate, double seconds);

  // One of the reference receivers, in this process, at `rate`.
  nlohmann::ordered_json reference_trial(ReferenceReceiver::Kind kind, double rate, double seconds);

 private:
  // The generator's options for one trial: the user's traffic, sent along the path.
  GeneratorOptions traffic(std::uint16_t port, double rate, double seconds) const;

  const ZeroLossOptions& o_;
  const TrafficSource& source_;
  std::filesystem::path work_;
  TrafficPath path_;
  std::filesystem::path daemon_;
  // Whether the daemon has --receiver (a pandarcapd from before the packet_ring receiver has
  // not, and receives with its socket only).
  bool daemon_has_receiver_option_ = false;
  int trials_ = 0;
  std::vector<std::filesystem::path> emptied_;  // the trials' outputs, removed at the end
};

}  // namespace pandarcap::bench
