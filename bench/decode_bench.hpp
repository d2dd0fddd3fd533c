// `pandarcap-bench decode`: packets/s and points/s per core of the scalar reference decoder and
// every SIMD target this machine runs, on one packet stream looped in memory, in one run.
//
// Rates are per CPU-second of the decoding thread (CLOCK_THREAD_CPUTIME_ID), so time the thread
// spent descheduled on a shared machine does not count against it. Targets are measured in
// interleaved rounds (scalar, sse4, avx2, ... then again) and each figure is the median round,
// so a noisy neighbour affects all targets alike and the ratios stay meaningful.
#pragma once

#include <cstdint>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/decode/decoder_target.hpp"
#include "core/sensors/sensor_model_id.hpp"

namespace pandarcap::bench {

struct DecodeBenchOptions {
  std::string capture;      // pcap/pcapng to loop; "" = the simulated sensor (dual return)
  std::string calibration;  // CSV; "" = the nominal table
  std::vector<DecoderTarget> targets;  // empty = every target this machine supports
  double seconds = 0.3;                // CPU time per target per round
  int rounds = 5;                      // interleaved rounds; figures are medians
  // Fixed-work mode for instruction counting (callgrind): decode the stream this many times with
  // each target and report only what was done, no timing.
  std::optional<int> passes;
  // Not empty: the per-model rows instead (model_decode_bench.cpp): each model's whole stream
  // decoder on one second of its simulated sensor, the 40P's at every target, the others' scalar.
  std::vector<SensorModelId> models;
};

// Runs the benchmark and returns the report. Throws std::runtime_error for an unusable capture.
nlohmann::ordered_json run_decode_bench(const DecodeBenchOptions& options);

void print_decode_report(const nlohmann::ordered_json& report);

// The per-model rows (options.models), and their table.
nlohmann::ordered_json run_model_decode_bench(const DecodeBenchOptions& options);
void print_model_decode_report(const nlohmann::ordered_json& report);

}  // namespace pandarcap::bench
