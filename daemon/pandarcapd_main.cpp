// pandarcapd: the Pandar40P capture daemon.
//
// This version runs the decode path offline: it replays a capture file (--replay) or first
// records the built-in simulated sensor into a capture file and then replays that (--simulate),
// printing one line per frame and a summary. Live UDP capture is not implemented yet.
//
// Start-up order: options -> logging -> calibration -> source -> decode -> summary.
#include <fmt/format.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <cmath>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>

#include "core/calibration.hpp"
#include "core/capture_reader.hpp"
#include "core/frame_collector.hpp"
#include "core/packet_time.hpp"
#include "core/pcap_writer.hpp"
#include "core/stream_decoder.hpp"
#include "core/synthetic_sensor.hpp"
#include "daemon/cli_args.hpp"

namespace {

using namespace pandarcap;

constexpr std::string_view kVersion = "0.1.0";

constexpr std::string_view kUsage = R"(Usage: pandarcapd --simulate [options]
       pandarcapd --replay FILE [options]

Decodes a Hesai Pandar40P packet stream into frames and prints one line per frame and a summary.
This version works offline; live UDP capture is not implemented yet.

Sources (one is required):
  --simulate             record the built-in simulated Pandar40P (a room with walls, floor,
                         a pillar and a fence) into OUTPUT-DIR/raw/simulated.pcap, then decode it
  --replay FILE          decode a pcap or pcapng capture

Simulation:
  --duration S           seconds of sensor data to generate (default 2, at most 3600)
  --rpm N                600 or 1200 (default 600)
  --return-mode MODE     dual, strongest or last (default dual)
  --udp-sequence         send 1266-byte packets with a UDP sequence number

Decoding:
  --calibration FILE     angle-correction CSV (default: the nominal Pandar40P table)
  --port N               replay only datagrams to destination port N (default: any)
  --cut-angle DEG        frame cut angle (default 0)
  --min-range M          default 0.3
  --max-range M          default 200
  --dual-return-distance-threshold M
                         default 0.1
  --firing-time-correction
                         correct each channel's azimuth for its firing time (default off)

General:
  --output-dir DIR       where recordings go (default ./pandarcap-output)
  --quiet                no per-frame lines, only the summary
  --log-level LEVEL      trace, debug, info, warn, error (default info)
  --version              print the version
  -h, --help             this text

Exit status: 0 done, 1 the capture ended in a corrupt record, 2 an input or output file could not
be used, 64 bad command line.
)";

struct Options {
  bool simulate = false;
  std::optional<std::string> replay;
  double duration_s = 2.0;
  SyntheticSensorConfig sensor;
  std::optional<std::string> calibration;
  std::optional<std::uint16_t> port;
  StreamDecoderConfig decode;
  std::filesystem::path output_dir = "pandarcap-output";
  bool quiet = false;
  spdlog::level::level_enum log_level = spdlog::level::info;
};

Options parse_options(int argc, char** argv) {
  Options o;
  CliArgs args(argc, argv, kUsage);
  while (args.more()) {
    const std::string_view arg = args.next();
    if (arg == "--simulate") {
      o.simulate = true;
    } else if (arg == "--replay") {
      o.replay = std::string(args.value(arg));
    } else if (arg == "--duration") {
      o.duration_s = args.number(arg, 0.001, 3600);
    } else if (arg == "--rpm") {
      o.sensor.rpm = static_cast<int>(args.integer(arg, 600, 1200));
      if (o.sensor.rpm != 600 && o.sensor.rpm != 1200) args.usage_error("--rpm takes 600 or 1200");
    } else if (arg == "--return-mode") {
      const std::string_view mode = args.value(arg);
      const auto parsed = return_mode_from_string(mode);
      if (!parsed) {
        args.usage_error(
            fmt::format("--return-mode takes dual, strongest or last, got '{}'", mode));
      }
      o.sensor.return_mode = *parsed;
    } else if (arg == "--udp-sequence") {
      o.sensor.udp_sequence = true;
    } else if (arg == "--calibration") {
      o.calibration = std::string(args.value(arg));
    } else if (arg == "--port") {
      o.port = static_cast<std::uint16_t>(args.integer(arg, 1, 65535));
    } else if (arg == "--cut-angle") {
      o.decode.cut_angle_deg = args.number(arg, 0.0, 360.0);
    } else if (arg == "--min-range") {
      o.decode.decoder.min_range_m = args.number(arg, 0.0, 262.14);
    } else if (arg == "--max-range") {
      o.decode.decoder.max_range_m = args.number(arg, 0.0, 262.14);
    } else if (arg == "--dual-return-distance-threshold") {
      o.decode.decoder.dual_return_distance_threshold_m = args.number(arg, 0.0, 262.14);
    } else if (arg == "--firing-time-correction") {
      o.decode.decoder.firing_time_correction = true;
    } else if (arg == "--output-dir") {
      o.output_dir = std::string(args.value(arg));
    } else if (arg == "--quiet") {
      o.quiet = true;
    } else if (arg == "--log-level") {
      const std::string level(args.value(arg));
      o.log_level = spdlog::level::from_str(level);
      if (o.log_level == spdlog::level::off && level != "off") {
        args.usage_error(fmt::format("unknown log level '{}'", level));
      }
    } else if (arg == "--version") {
      fmt::print("pandarcapd {}\n", kVersion);
      std::exit(0);
    } else {
      args.usage_error(fmt::format("unknown option '{}'", arg));
    }
  }
  if (o.simulate == o.replay.has_value()) {
    args.usage_error("give exactly one source: --simulate or --replay FILE");
  }
  if (o.decode.decoder.min_range_m > o.decode.decoder.max_range_m) {
    args.usage_error("--min-range is larger than --max-range");
  }
  return o;
}

// Records `duration_s` of the simulated sensor into a classic pcap; returns its path.
std::filesystem::path record_simulation(const Options& o, const Calibration& calibration) {
  const std::filesystem::path raw_dir = o.output_dir / "raw";
  std::filesystem::create_directories(raw_dir);
  const std::filesystem::path path = raw_dir / "simulated.pcap";
  SyntheticSensor sensor(o.sensor, calibration);
  PcapWriter writer(path.string());
  const Endpoint source{0xC0A801C9, 2368};       // 192.168.1.201, the sensor's factory address
  const Endpoint destination{0xC0A8010A, 2368};  // 192.168.1.10
  const auto packets = static_cast<std::uint64_t>(
      std::llround(o.duration_s * 1e9 / static_cast<double>(sensor.packet_period_ns())));
  std::array<std::uint8_t, kMaxPacketBytes> buffer{};
  for (std::uint64_t i = 0; i < packets; ++i) {
    const std::size_t size = sensor.next(buffer);
    writer.write(std::span(buffer).first(size), sensor.last_packet_time_ns(), source, destination);
  }
  writer.close();
  spdlog::info("simulated sensor: {} packets ({} s, {} RPM, {} return{}) recorded to {}", packets,
               o.duration_s, o.sensor.rpm, to_string(o.sensor.return_mode),
               o.sensor.udp_sequence ? ", UDP sequence" : "", path.string());
  return path;
}

std::string format_time(std::int64_t ns, bool valid) {
  if (!valid) return fmt::format("(no valid date) +{:.6f} s", static_cast<double>(ns) / 1e9);
  const std::int64_t seconds = ns >= 0 ? ns / 1'000'000'000 : (ns + 1) / 1'000'000'000 - 1;
  const TailDateTime utc = tail_datetime_from_unix(seconds);
  return fmt::format("{:04}-{:02}-{:02}T{:02}:{:02}:{:02}.{:03}Z", 2000 + utc.year_since_2000,
                     utc.month, utc.day, utc.hour, utc.minute, utc.second,
                     (ns - seconds * 1'000'000'000) / 1'000'000);
}

int run(const Options& o) {
  Calibration calibration = Calibration::nominal();
  if (o.calibration) {
    calibration = Calibration::load(*o.calibration);
    spdlog::info("calibration: {}", calibration.source);
  } else {
    spdlog::warn(
        "calibration: nominal Pandar40P table in use (no --calibration given); per-unit "
        "elevations differ by up to ~0.45 degrees");
  }

  const std::filesystem::path input =
      o.simulate ? record_simulation(o, calibration) : std::filesystem::path(*o.replay);
  CaptureReader reader(input.string(), CaptureReader::Options{o.port});

  FrameCollector collector(3, kDefaultFrameCapacityPoints, [&](const Frame& frame) {
    const FrameInfo& f = frame.info;
    if (o.quiet) return;
    fmt::print(
        "frame {:>4}  {:>6} points  {:>4} packets  {:>6.1f} rpm  {:<9}  {:<8}  {}  {:.1f} ms\n",
        f.sequence, f.points, f.packets, f.rpm, to_string(f.return_mode),
        f.partial ? "partial" : "complete", format_time(f.start_ns, f.time_valid),
        static_cast<double>(f.end_ns - f.start_ns) / 1e6);
  });
  StreamDecoder decoder(calibration, o.decode, collector);

  CaptureRecord record;
  CaptureStatus status;
  while ((status = reader.next(record)) == CaptureStatus::kRecord)
    decoder.process(record.payload);
  decoder.flush();

  const StreamStats& s = decoder.stats();
  const AssemblerStats& fs = decoder.frames();
  fmt::print(
      "\n{}: {} packets, {} accepted, {} rejected; {} frames complete, {} partial, {} dropped; "
      "{} points ({} filtered); rpm {}..{}; return mode {}\n",
      input.string(), s.packets, s.accepted, s.rejected(), fs.frames_complete, fs.frames_partial,
      fs.frames_dropped, s.points, s.filtered.total(), s.rpm_min, s.rpm_max,
      s.return_mode ? to_string(*s.return_mode) : "none");
  if (status != CaptureStatus::kEnd) spdlog::warn("{}", reader.error());
  return status == CaptureStatus::kError ? 1 : 0;
}

}  // namespace

int main(int argc, char** argv) {
  const Options options = parse_options(argc, argv);
  // Logs go to stderr; stdout carries the frame lines and the summary.
  spdlog::set_default_logger(spdlog::stderr_color_mt("pandarcapd"));
  spdlog::set_level(options.log_level);
  try {
    return run(options);
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 2;
  }
}
