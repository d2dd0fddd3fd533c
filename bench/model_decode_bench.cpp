// `pandarcap-bench decode --sensor-model M`: each model's whole stream decoder
// (BasicStreamDecoder<M>: validation, duplicates, packet time, the outlier rule, decode with
// points on, frame assembly into a collector) on one second of its simulated sensor
// (AnyModelSensor, dual return, 600 RPM), per CPU-second of one thread. The Pandar40P runs at
// every decoder target (its SIMD kernels); the others have the generic scalar decoder only
// (core/decode/model_decoder.hpp), so theirs is one scalar row. Rows are measured in interleaved
// rounds and each figure is the median, as the 40P's target rows (decode_bench.cpp).
//
// A pass is the second of packets through a fresh decoder (made before the clock starts), then
// flush(): the stream's start is in every pass, as a replay's is.
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <memory>
#include <stdexcept>
#include <type_traits>
#include <vector>

#include "bench/decode_bench.hpp"
#include "bench/median.hpp"
#include "core/decode/calibration.hpp"
#include "core/decode/stream_decoder.hpp"
#include "core/frames/frame_collector.hpp"
#include "core/sensors/sensor_models.hpp"
#include "core/sim/any_model_sensor.hpp"
#include "daemon/clocks.hpp"

namespace pandarcap::bench {

namespace {

constexpr int kRpm = 600;
constexpr ReturnMode kMode = ReturnMode::kDual;

// One row: a model at a decoder target, its second of packets back to back.
struct Row {
  SensorModelId model;
  DecoderTarget target;
  std::vector<std::uint8_t> bytes;
  std::vector<std::size_t> offsets, sizes;
  int slots_per_packet = 0;      // blocks × channels: the channel measurements a packet holds
  double sensor_pps = 0;         // the model's own rate in kMode
  std::size_t frame_points = 0;  // a frame's capacity: a revolution's slots and a fifth more
  std::vector<double> packets_per_s, points_per_s;
  // The last pass's counts (every pass decodes the same bytes the same way).
  StreamStats stats;
  AssemblerStats frames;
};

Row make_row(SensorModelId model, DecoderTarget target) {
  Row row{model, target, {}, {}, {}, 0, 0, 0, {}, {}, {}, {}};
  ModelSensorConfig config;
  config.rpm = kRpm;
  config.return_mode = kMode;
  AnyModelSensor sensor(model, config);
  with_model(model, [&]<class M>(std::type_identity<M>) {
    const int returns = returns_per_firing(kMode);
    row.slots_per_packet = M::kBlocks * M::kChannels;
    row.sensor_pps = M::packets_per_second(returns);
    row.frame_points = static_cast<std::size_t>(M::packets_per_revolution(returns, kRpm) * 1.2) *
                       static_cast<std::size_t>(row.slots_per_packet);
  });
  std::array<std::uint8_t, kLargestDatagramBytes> buffer{};
  const auto count = static_cast<std::size_t>(std::llround(row.sensor_pps));
  for (std::size_t k = 0; k < count; ++k) {
    const std::size_t size = sensor.next(buffer);
    row.offsets.push_back(row.bytes.size());
    row.sizes.push_back(size);
    row.bytes.insert(row.bytes.end(), buffer.begin(), buffer.begin() + static_cast<long>(size));
  }
  return row;
}

// Thread CPU seconds of `passes` passes of the row's packets through fresh decoders.
template <class M>
double timed_passes(Row& row, int passes) {
  std::uint64_t points = 0;
  FrameCollector sink(3, row.frame_points, [&](const Frame& frame) { points += frame.size; });
  StreamDecoderConfig config;
  config.decoder_target = row.target;
  const Calibration calibration = Calibration::nominal(row.model);
  double elapsed = 0;
  for (int p = 0; p < passes; ++p) {
    auto decoder = std::make_unique<BasicStreamDecoder<M>>(calibration, config, sink);
    const double start = thread_cpu_seconds();
    for (std::size_t k = 0; k < row.sizes.size(); ++k)
      decoder->process({row.bytes.data() + row.offsets[k], row.sizes[k]});
    decoder->flush();
    elapsed += thread_cpu_seconds() - start;
    row.stats = decoder->stats();
    row.frames = decoder->frames();
  }
  asm volatile("" : : "r"(&points) : "memory");
  return std::max(1e-9, elapsed);
}

void measure_row(Row& row, double seconds) {
  with_model(row.model, [&]<class M>(std::type_identity<M>) {
    const double one_pass = timed_passes<M>(row, 1);
    const int passes = std::clamp(static_cast<int>(seconds / one_pass), 1, 1'000'000);
    const double elapsed = timed_passes<M>(row, passes);
    const double packets = static_cast<double>(row.sizes.size()) * passes;
    row.packets_per_s.push_back(packets / elapsed);
    row.points_per_s.push_back(static_cast<double>(row.stats.points) * passes / elapsed);
  });
}

}  // namespace

nlohmann::ordered_json run_model_decode_bench(const DecodeBenchOptions& options) {
  if (!options.capture.empty() || !options.calibration.empty() || options.passes) {
    throw std::invalid_argument(
        "--sensor-model decodes each model's simulated sensor with its nominal table, timed: "
        "--capture, --calibration and --passes are the Pandar40P's rows'");
  }
  std::vector<DecoderTarget> targets = options.targets;
  if (targets.empty()) targets = supported_decoder_targets();
  std::vector<Row> rows;
  for (const SensorModelId model : options.models) {
    if (model == SensorModelId::kPandar40P) {
      for (const DecoderTarget target : targets)
        rows.push_back(make_row(model, target));
    } else {
      rows.push_back(make_row(model, DecoderTarget::kScalar));  // no SIMD kernel
    }
  }
  for (int round = 0; round < options.rounds; ++round) {
    for (Row& row : rows)
      measure_row(row, options.seconds);
  }

  nlohmann::ordered_json report;
  report["input"] = {
      {"source", fmt::format("each model's simulated sensor, {} return, {} RPM, one second of "
                             "packets; its nominal calibration",
                             to_string(kMode), kRpm)},
      {"return_mode", std::string(to_string(kMode))},
      {"rpm", kRpm}};
  double reference = 0;  // the 40P's scalar ns per channel measurement
  nlohmann::ordered_json list = nlohmann::ordered_json::array();
  for (const Row& row : rows) {
    const double pps = median(row.packets_per_s);
    const double measurements = pps * row.slots_per_packet;
    const double ns_per_measurement = 1e9 / measurements;
    if (row.model == SensorModelId::kPandar40P && row.target == DecoderTarget::kScalar) {
      reference = ns_per_measurement;
    }
    list.push_back(
        {{"sensor_model", std::string(lower_case_name(row.model))},
         {"target", std::string(to_string(row.target))},
         {"packets", row.sizes.size()},
         {"slots_per_packet", row.slots_per_packet},
         {"packets_per_s", pps},
         {"channel_measurements_per_s", measurements},
         {"ns_per_measurement", ns_per_measurement},
         {"ns_per_packet", 1e9 / pps},
         {"points_per_s", median(row.points_per_s)},
         {"sensor_packets_per_s", row.sensor_pps},
         {"sensor_fraction_of_core", row.sensor_pps / pps},
         {"accepted", row.stats.accepted},
         {"rejected", row.stats.rejected()},
         {"outliers", row.stats.outliers},
         {"points_per_pass", row.stats.points},
         {"frames_complete", row.frames.frames_complete},
         {"frames_dropped", row.frames.frames_dropped},
         {"points_dropped", row.frames.points_dropped_full + row.frames.points_dropped_no_frame +
                                row.frames.points_late},
         {"rounds_packets_per_s", row.packets_per_s}});
  }
  for (auto& entry : list) {
    entry["ns_per_measurement_vs_pandar40p_scalar"] =
        reference > 0 ? entry["ns_per_measurement"].get<double>() / reference : 0.0;
  }
  report["models"] = list;
  report["method"] = fmt::format(
      "{} interleaved rounds of >= {} s thread CPU time per row; medians; one thread; "
      "BasicStreamDecoder<Model> with points on, frames into a collector",
      options.rounds, options.seconds);
  return report;
}

void print_model_decode_report(const nlohmann::ordered_json& report) {
  std::printf("input: %s\n", report["input"]["source"].get<std::string>().c_str());
  std::printf("%-12s %-7s %12s %15s %8s %9s %14s %10s\n", "model", "target", "packets/s",
              "measurements/s", "ns/meas", "vs 40P", "points/s", "1 sensor");
  for (const auto& row : report["models"]) {
    std::printf(
        "%-12s %-7s %12.0f %15.0f %8.2f %8.2fx %14.0f %9.1f%%\n",
        row["sensor_model"].get<std::string>().c_str(), row["target"].get<std::string>().c_str(),
        row["packets_per_s"].get<double>(), row["channel_measurements_per_s"].get<double>(),
        row["ns_per_measurement"].get<double>(),
        row["ns_per_measurement_vs_pandar40p_scalar"].get<double>(),
        row["points_per_s"].get<double>(), 100 * row["sensor_fraction_of_core"].get<double>());
  }
  std::printf(
      "vs 40P: ns per measurement against the Pandar40P's scalar row; 1 sensor: the share "
      "of one core the model's own stream (dual, 600 RPM) takes\n");
}

}  // namespace pandarcap::bench
