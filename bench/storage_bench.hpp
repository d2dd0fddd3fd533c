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

namespace pandarcap::bench {

struct StorageBenchOptions {
  double seconds = 8;     // the measured window of each run
  int rounds = 1;         // runs of each configuration, interleaved; medians reported
  std::string directory;  // where the runs write; "" = a temporary directory, removed
  std::string daemon;     // pandarcapd; "" = the one beside pandarcap-bench
  std::string only;       // only the configurations whose name holds this (and the reference)
};

nlohmann::ordered_json run_storage_bench(const StorageBenchOptions& options);

// Prints the report as a Markdown table (the one docs/storage.md shows).
void print_storage_report(const nlohmann::ordered_json& report);

}  // namespace pandarcap::bench
