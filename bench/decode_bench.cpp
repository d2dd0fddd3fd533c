#include "bench/decode_bench.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <stdexcept>

#include "bench/median.hpp"
#include "core/decode/calibration.hpp"
#include "core/decode/packet_decoder.hpp"
#include "core/decode/simd_decoder.hpp"
#include "core/sim/synthetic_sensor.hpp"
#include "daemon/clocks.hpp"
#include "daemon/io/calibration_file.hpp"
#include "daemon/pcap/capture_reader.hpp"

namespace pandarcap::bench {

namespace {

// The stream to decode: valid payloads back to back.
struct Stream {
  std::vector<std::uint8_t> bytes;
  std::vector<std::size_t> offsets, sizes;
  std::string source;
  std::string return_mode;
  std::size_t skipped = 0;  // records that were not valid Pandar40P packets

  void add(std::span<const std::uint8_t> payload) {
    offsets.push_back(bytes.size());
    sizes.push_back(payload.size());
    bytes.insert(bytes.end(), payload.begin(), payload.end());
  }
  std::size_t packets() const { return sizes.size(); }
  PacketView packet(std::size_t k) const {
    return PacketView::assume_valid({bytes.data() + offsets[k], sizes[k]});
  }
};

Stream load_stream(const DecodeBenchOptions& options) {
  Stream stream;
  if (options.capture.empty()) {
    // One second of the simulated sensor in dual return: 3600 packets.
    SyntheticSensor sensor({});
    std::array<std::uint8_t, kMaxPacketBytes> buffer{};
    for (int k = 0; k < 3600; ++k) {
      const std::size_t size = sensor.next(buffer);
      stream.add({buffer.data(), size});
    }
    stream.source = "simulated Pandar40P, dual return, 600 RPM, 3600 packets";
  } else {
    CaptureReader reader(options.capture);
    CaptureRecord record;
    CaptureStatus status;
    while ((status = reader.next(record)) == CaptureStatus::kRecord) {
      if (validate(record.payload) == RejectReason::kNone) {
        stream.add(record.payload);
      } else {
        ++stream.skipped;
      }
    }
    if (stream.packets() == 0) {
      throw std::runtime_error(fmt::format("{}: no valid Pandar40P packets", options.capture));
    }
    stream.source = options.capture;
  }
  stream.return_mode = std::string(to_string(stream.packet(0).return_mode()));
  return stream;
}

// Decodes the whole stream `passes` times; returns the points written. Kept out of line so
// callgrind can count exactly this function (--toggle-collect='*decode_passes*').
[[gnu::noinline]] std::uint64_t decode_passes(const PacketDecoder& decoder, const Stream& stream,
                                              int passes) {
  std::array<Point, kMaxPointsPerPacket> points;
  FilterCounts filtered;
  std::uint64_t total = 0;
  for (int p = 0; p < passes; ++p) {
    for (std::size_t k = 0; k < stream.packets(); ++k) {
      total += decoder.decode(stream.packet(k), static_cast<std::int64_t>(k), points, filtered)
                   .point_count;
    }
  }
  // Keeps the stores observable.
  asm volatile("" : : "r"(points.data()) : "memory");
  return total;
}

struct Sample {
  double packets_per_s = 0, points_per_s = 0;
};

Sample measure(const PacketDecoder& decoder, const Stream& stream, double seconds) {
  // Size the run from one pass, then time enough passes to fill `seconds` of CPU.
  double start = thread_cpu_seconds();
  decode_passes(decoder, stream, 1);
  const double one_pass_s = std::max(1e-9, thread_cpu_seconds() - start);
  const int passes = std::clamp(static_cast<int>(seconds / one_pass_s), 1, 1'000'000);
  start = thread_cpu_seconds();
  const std::uint64_t points = decode_passes(decoder, stream, passes);
  const double elapsed = std::max(1e-9, thread_cpu_seconds() - start);
  return {static_cast<double>(stream.packets()) * passes / elapsed,
          static_cast<double>(points) / elapsed};
}

}  // namespace

nlohmann::ordered_json run_decode_bench(const DecodeBenchOptions& options) {
  if (!options.models.empty()) return run_model_decode_bench(options);
  const Stream stream = load_stream(options);
  const Calibration calibration =
      options.calibration.empty() ? Calibration::nominal() : load_calibration(options.calibration);
  std::vector<DecoderTarget> targets = options.targets;
  if (targets.empty()) targets = supported_decoder_targets();

  std::vector<PacketDecoder> decoders;
  for (const DecoderTarget target : targets)
    decoders.emplace_back(calibration, DecoderConfig{}, target);

  nlohmann::ordered_json report;
  report["input"] = {{"source", stream.source},
                     {"packets", stream.packets()},
                     {"skipped_records", stream.skipped},
                     {"return_mode", stream.return_mode},
                     {"calibration", calibration.source}};

  if (options.passes) {
    for (const PacketDecoder& decoder : decoders) {
      const std::uint64_t points = decode_passes(decoder, stream, *options.passes);
      report[std::string(to_string(decoder.target()))] = {
          {"packets_decoded", stream.packets() * static_cast<std::uint64_t>(*options.passes)},
          {"points_decoded", points}};
    }
    return report;
  }

  std::vector<std::vector<Sample>> samples(decoders.size());
  for (int round = 0; round < options.rounds; ++round) {
    for (std::size_t i = 0; i < decoders.size(); ++i)
      samples[i].push_back(measure(decoders[i], stream, options.seconds));
  }

  double scalar_rate = 0;
  std::string best;
  double best_rate = 0;
  nlohmann::ordered_json ran = nlohmann::ordered_json::array();
  for (std::size_t i = 0; i < decoders.size(); ++i) {
    std::vector<double> packets, points;
    for (const Sample& s : samples[i]) {
      packets.push_back(s.packets_per_s);
      points.push_back(s.points_per_s);
    }
    const double rate = median(packets);
    const std::string name(to_string(decoders[i].target()));
    if (decoders[i].target() == DecoderTarget::kScalar) scalar_rate = rate;
    if (rate > best_rate) {
      best_rate = rate;
      best = name;
    }
    ran.push_back(name);
    report[name] = {{"packets_per_s", rate},
                    {"points_per_s", median(points)},
                    {"ns_per_packet", 1e9 / rate},
                    {"channel_measurements_per_s", rate * kBlocks * kChannels},
                    {"rounds_packets_per_s", packets}};
  }
  for (const auto& name : ran) {
    const std::string key = name.get<std::string>();
    report[key]["vs_scalar"] =
        scalar_rate > 0 ? report[key]["packets_per_s"].get<double>() / scalar_rate : 0.0;
  }
  report["targets_ran"] = ran;
  report["best_target"] = best;
  report["best_vs_scalar"] = scalar_rate > 0 ? best_rate / scalar_rate : 0.0;
  report["auto_target"] = std::string(to_string(best_decoder_target()));
  const double measurements = best_rate * kBlocks * kChannels;
  report["goals"] = {{"best_vs_scalar_at_least_4", scalar_rate > 0 && best_rate >= 4 * scalar_rate},
                     {"channel_measurements_per_s_at_least_1_5e9", measurements >= 1.5e9},
                     {"sensor_dual_stream_fraction_of_core", 3600.0 / best_rate}};
  report["method"] = fmt::format(
      "{} interleaved rounds of >= {} s thread CPU time per target; medians; one thread",
      options.rounds, options.seconds);
  return report;
}

void print_decode_report(const nlohmann::ordered_json& report) {
  if (report.contains("models")) {
    print_model_decode_report(report);
    return;
  }
  std::printf("input: %s (%zu packets, %s)\n", report["input"]["source"].get<std::string>().c_str(),
              report["input"]["packets"].get<std::size_t>(),
              report["input"]["return_mode"].get<std::string>().c_str());
  if (!report.contains("targets_ran")) {
    std::puts(report.dump(2).c_str());
    return;
  }
  std::printf("%-8s %16s %16s %12s %10s\n", "target", "packets/s", "points/s", "ns/packet",
              "vs scalar");
  for (const auto& name : report["targets_ran"]) {
    const auto& t = report[name.get<std::string>()];
    std::printf("%-8s %16.0f %16.0f %12.1f %9.2fx\n", name.get<std::string>().c_str(),
                t["packets_per_s"].get<double>(), t["points_per_s"].get<double>(),
                t["ns_per_packet"].get<double>(), t["vs_scalar"].get<double>());
  }
  std::printf(
      "best: %s, %.2fx scalar; auto picks %s\n", report["best_target"].get<std::string>().c_str(),
      report["best_vs_scalar"].get<double>(), report["auto_target"].get<std::string>().c_str());
}

}  // namespace pandarcap::bench
