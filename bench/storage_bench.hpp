// `pandarcap-bench storage`: what each choice of outputs costs a vehicle's disk and CPU. The real
// pandarcapd runs with its simulated Pandar40P (dual return, 600 RPM: 3600 packets/s) once per
// configuration: health only (the reference), raw packets as pcap and as pcap.zst, PCD frames
// plain, LZF-compressed and decimated, MCAP, the defaults, and the packaged vehicle profile
// (systemd/front.toml's outputs). For each, over a window of traffic: the bytes each output
// directory grew by (MB/s, GB per hour, hours per TB) and the daemon's CPU in % of one core,
// without the simulated sensor's own thread, from /proc/PID/task/*/stat. With --rounds N the
// configurations run N times interleaved and the medians are reported (a shared machine's noise
// hits every configuration alike).
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <string_view>

namespace pandarcap::bench {

struct StorageBenchOptions {
  double seconds = 8;     // the measured window of each run
  int rounds = 1;         // runs of each configuration, interleaved; medians reported
  std::string directory;  // where the runs write; "" = a temporary directory, removed
  std::string daemon;     // pandarcapd; "" = the one beside pandarcap-bench
  std::string only;       // only the configurations whose name holds this (and the reference)
};

inline constexpr std::string_view kStorageUsage = R"(Usage: pandarcap-bench storage [OPTIONS]

Runs pandarcapd with its simulated sensor (3600 packets/s) once per choice of outputs and
measures, over a window of traffic, the bytes written (MB/s, GB per hour, hours per TB) and the
daemon's CPU (% of one core, without the simulated sensor's thread).

Options:
  --json               print one JSON object instead of a Markdown table
  --seconds S          the measured window of each run (default 8)
  --rounds N           run every configuration N times, interleaved; medians (default 1)
  --dir DIR            where the runs write (default: a temporary directory, removed)
  --daemon PATH        pandarcapd (default: the one beside pandarcap-bench)
  --only TEXT          only the configurations whose name holds TEXT (and the reference)
  -h, --help           this text

JSON keys: rows[] (name, config, packets_per_s, mb_per_s, mb_per_s_by_output {frames, raw,
mcap, health}, gb_per_hour, hours_per_tb, cpu_fraction_of_core, cpu_over_reference,
writer_cpu_fraction_of_core), seconds, rounds, method.
)";

nlohmann::ordered_json run_storage_bench(const StorageBenchOptions& options);

// Prints the report as a Markdown table (the one docs/storage.md shows).
void print_storage_report(const nlohmann::ordered_json& report);

}  // namespace pandarcap::bench
