// `pandarcap-bench ring`: throughput and round-trip latency of the packet ring (batches of 1, 8
// and 32) and the typed queue, next to a mutex + condition-variable queue measured in the same
// run, and the CPU an idle consumer burns at the sensor's packet rate.
#pragma once

#include <cstddef>
#include <cstdint>
#include <nlohmann/json.hpp>

namespace pandarcap::bench {

struct RingBenchOptions {
  std::uint64_t ring_items = 20'000'000;  // per packet-ring and typed-queue throughput run
  std::uint64_t mutex_items = 2'000'000;  // the baseline is ~100x slower: fewer items, same rate
  std::uint64_t round_trips = 100'000;    // per latency measurement
  int repeat = 3;                         // each figure is the median of this many runs
  std::size_t capacity = 1024;            // slots in every ring and queue
  double idle_seconds = 2.0;              // length of the idle-CPU measurement
};

// Runs everything and returns the report (see docs/performance.md for the keys).
nlohmann::ordered_json run_ring_bench(const RingBenchOptions& options);

// Prints the report as a short table.
void print_ring_report(const nlohmann::ordered_json& report);

}  // namespace pandarcap::bench
