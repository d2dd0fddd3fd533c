#include "bench/write_bench.hpp"

#include <fmt/format.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <vector>

#include "core/decode/pcd_simd_encoder.hpp"
#include "core/decode/stream_decoder.hpp"
#include "core/frames/frame_collector.hpp"
#include "core/frames/pcd.hpp"
#include "core/frames/pcd_compressed.hpp"
#include "core/sim/synthetic_sensor.hpp"
#include "daemon/clocks.hpp"
#include "daemon/io/file_output.hpp"
#include "daemon/pcap/pcap_writer.hpp"

namespace pandarcap::bench {

namespace {

namespace fs = std::filesystem;

// Wall and thread-CPU time of `work`, in seconds.
template <typename Work>
std::pair<double, double> timed(Work&& work) {
  const std::int64_t wall = monotonic_ns();
  const double cpu = thread_cpu_seconds();
  work();
  return {static_cast<double>(monotonic_ns() - wall) / 1e9, thread_cpu_seconds() - cpu};
}

// One complete revolution of the simulated sensor, decoded.
std::vector<Point> one_frame() {
  std::vector<Point> points;
  FrameCollector collector(4, 200'000, [&](const Frame& frame) {
    if (!frame.info.partial && points.empty()) {
      points.assign(frame.used().begin(), frame.used().end());
    }
  });
  StreamDecoder decoder(Calibration::nominal(), {}, collector);
  SyntheticSensor sensor({});
  std::array<std::uint8_t, kMaxPacketBytes> packet{};
  while (points.empty()) {
    const std::size_t size = sensor.next(packet);
    decoder.process({packet.data(), size});
  }
  return points;
}

// The frame cut's encoding into each layout (what the arena gets), the scalar reference against
// the SIMD encoder (the target the daemon picks), in runs of 160 points (about what one packet
// adds to a frame), the two interleaved in the same run.
nlohmann::ordered_json simd_encoding(const std::vector<Point>& frame, int frames) {
  constexpr std::size_t kRun = 160;
  const PcdEncoder simd;
  std::vector<std::uint8_t> arena(frame.size() * kMaxPcdPointBytes);
  nlohmann::ordered_json report;
  report["target"] = std::string(to_string(simd.target()));
  for (const PcdLayout layout :
       {PcdLayout::kPcl, PcdLayout::kPandarcap, PcdLayout::kVelodyne, PcdLayout::kAutoware}) {
    const PcdFormat format{layout, Axes::kHesai};
    const PcdFrameContext context{frame.front().timestamp_ns, ReturnMode::kDual};
    const std::size_t step = pcd_point_bytes(layout);
    const auto encode = [&](bool vector) {
      for (std::size_t i = 0; i < frame.size(); i += kRun) {
        const auto run = std::span(frame).subspan(i, std::min(kRun, frame.size() - i));
        const auto out = std::span(arena).subspan(i * step, run.size() * step);
        if (vector) {
          simd.encode(run, out, format, context);
        } else {
          encode_pcd_points(run, out, format, context);
        }
      }
    };
    double scalar_cpu = 0, simd_cpu = 0;
    for (int f = 0; f < frames; ++f) {
      scalar_cpu += timed([&] { encode(false); }).second;
      simd_cpu += timed([&] { encode(true); }).second;
    }
    const double points = static_cast<double>(frame.size()) * frames;
    report[std::string(to_string(layout))] = {{"scalar_points_per_cpu_s", points / scalar_cpu},
                                              {"simd_points_per_cpu_s", points / simd_cpu},
                                              {"simd_speedup", scalar_cpu / simd_cpu}};
  }
  return report;
}

}  // namespace

nlohmann::ordered_json run_write_bench(const WriteBenchOptions& o) {
  const bool temporary = o.directory.empty();
  const fs::path dir =
      temporary ? fs::temp_directory_path() / fmt::format("pandarcap-write-{}", ::getpid())
                : fs::path(o.directory);
  fs::create_directories(dir);

  const std::vector<Point> frame = one_frame();
  std::vector<std::uint8_t> buffer(4096 * kPcdPointBytes);
  const auto encode = [&](OutputFile* file) {
    if (file) file->write(pcd_header(frame.size()));
    for (std::size_t i = 0; i < frame.size(); i += 4096) {
      const auto chunk = std::span(frame).subspan(i, std::min<std::size_t>(4096, frame.size() - i));
      const std::size_t n = encode_pcd_points(chunk, buffer);
      if (file) file->write(std::span<const std::uint8_t>(buffer.data(), n));
    }
  };
  const double points = static_cast<double>(frame.size()) * o.frames;
  const double pcd_bytes = points * kPcdPointBytes;
  const auto [encode_wall, encode_cpu] = timed([&] {
    for (int f = 0; f < o.frames; ++f)
      encode(nullptr);
  });
  // The same frames as DATA binary_compressed (output.pcd_compression = "lzf"): encoded,
  // transposed and compressed, not written.
  PcdCompressor compressor;
  compressor.reserve(frame.size(), PcdLayout::kPandarcap);
  std::size_t lzf_bytes = 0;
  const auto [lzf_wall, lzf_cpu] = timed([&] {
    for (int f = 0; f < o.frames; ++f)
      lzf_bytes = compressor.compress(frame, {PcdLayout::kPandarcap, Axes::kHesai}, {}).size();
  });
  OutputFile file;
  const auto [write_wall, write_cpu] = timed([&] {
    for (int f = 0; f < o.frames; ++f) {
      file.open((dir / fmt::format("frame_{:03}.pcd", f)).native(), OutputFile::Mode::kCreate);
      encode(&file);
      file.close();
    }
  });

  SyntheticSensor sensor({});
  std::array<std::uint8_t, kMaxPacketBytes> packet{};
  const std::size_t size = sensor.next(packet);
  std::uint64_t pcap_bytes = 0;
  std::vector<char> pcap_buffer(kPcapBufferBytes);  // as the daemon's writer has
  const auto [pcap_wall, pcap_cpu] = timed([&] {
    PcapWriter pcap((dir / "bench.pcap").string(), pcap_buffer);
    for (int k = 0; k < o.packets; ++k) {
      pcap.write({packet.data(), size}, 1'795'348'800'000'000'000 + k * 277'800LL,
                 Endpoint{0xC0A801C9, 2368}, Endpoint{0xFFFFFFFF, 2368});
    }
    pcap.close();
    pcap_bytes = pcap.bytes();
  });

  if (temporary) {
    std::error_code ec;
    fs::remove_all(dir, ec);
  }
  const auto rates = [](double items, double bytes, double wall, double cpu) {
    return nlohmann::ordered_json{{"items_per_s", items / wall},
                                  {"mb_per_s", bytes / wall / 1e6},
                                  {"items_per_cpu_s", items / cpu},
                                  {"cpu_fraction_of_wall", cpu / wall}};
  };
  nlohmann::ordered_json report;
  report["points_per_frame"] = frame.size();
  report["pcd_encode"] = rates(points, pcd_bytes, encode_wall, encode_cpu);
  report["pcd_encode_and_write"] = rates(points, pcd_bytes, write_wall, write_cpu);
  report["pcd_encode_lzf"] = rates(points, pcd_bytes, lzf_wall, lzf_cpu);
  report["pcd_lzf_size_ratio"] =
      static_cast<double>(lzf_bytes) / static_cast<double>(frame.size() * kPcdPointBytes);
  report["pcd_cpu_us_per_frame"] = {{"binary", encode_cpu / o.frames * 1e6},
                                    {"lzf", lzf_cpu / o.frames * 1e6}};
  report["pcap_write"] = rates(o.packets, static_cast<double>(pcap_bytes), pcap_wall, pcap_cpu);
  report["pcd_encode_simd"] = simd_encoding(frame, o.frames);
  // What one dual-return sensor needs: 10 frames/s of this size and 3600 packets/s.
  report["sensor_pcd_cpu_fraction"] =
      10.0 * static_cast<double>(frame.size()) /
      report["pcd_encode_and_write"]["items_per_cpu_s"].get<double>();
  report["sensor_pcap_cpu_fraction"] =
      3600.0 / report["pcap_write"]["items_per_cpu_s"].get<double>();
  report["method"] =
      "one thread; items are points (PCD) or packets (pcap); files in a temporary directory";
  return report;
}

void print_write_report(const nlohmann::ordered_json& report) {
  std::printf("%-22s %14s %10s %16s\n", "", "items/s", "MB/s", "items/CPU-s");
  for (const char* key : {"pcd_encode", "pcd_encode_lzf", "pcd_encode_and_write", "pcap_write"}) {
    const auto& r = report[key];
    std::printf("%-22s %14.0f %10.1f %16.0f\n", key, r["items_per_s"].get<double>(),
                r["mb_per_s"].get<double>(), r["items_per_cpu_s"].get<double>());
  }
  std::printf("PCD frame CPU: %.0f us binary, %.0f us lzf (%.2f of the size)\n",
              report["pcd_cpu_us_per_frame"]["binary"].get<double>(),
              report["pcd_cpu_us_per_frame"]["lzf"].get<double>(),
              report["pcd_lzf_size_ratio"].get<double>());
  std::printf("one sensor: PCD %.2f %% of a core, pcap %.2f %% of a core\n",
              100 * report["sensor_pcd_cpu_fraction"].get<double>(),
              100 * report["sensor_pcap_cpu_fraction"].get<double>());
  const auto& simd = report["pcd_encode_simd"];
  std::printf("frame-cut encoding, %s against scalar (points/CPU-s):\n",
              simd["target"].get<std::string>().c_str());
  for (const auto& [layout, r] : simd.items()) {
    if (layout == "target") continue;
    std::printf("  %-10s %14.0f %14.0f  %.2fx\n", layout.c_str(),
                r["scalar_points_per_cpu_s"].get<double>(),
                r["simd_points_per_cpu_s"].get<double>(), r["simd_speedup"].get<double>());
  }
}

}  // namespace pandarcap::bench
