// pandarcap-inspect: per-packet field dump and summary of a capture of any supported Hesai model
// (pcap / pcapng, either compressed with zstd, or the PandarPacket messages of an MCAP file). The
// model is the recording's (its first packets name it, as a replay's do) or --sensor-model's.
//
// Exit status: 0 the capture was read whole, 1 it is not (damaged, cut short, or records with
// damaged headers: what was read is still summarised), 2 the capture or the calibration file
// cannot be used, 64 bad command line.
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <nlohmann/json.hpp>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "config/command_line.hpp"
#include "config/config_loader.hpp"
#include "core/decode/any_stream_decoder.hpp"
#include "core/decode/calibration.hpp"
#include "core/frames/frame_collector.hpp"
#include "core/frames/topdown_render.hpp"
#include "core/sensors/packet.hpp"
#include "core/sensors/sensor_models.hpp"
#include "daemon/cli_args.hpp"
#include "daemon/inspect/packet_fields.hpp"
#include "daemon/inspect/png_file.hpp"
#include "daemon/io/calibration_file.hpp"
#include "daemon/pcap/capture_reader.hpp"
#include "daemon/pcap/recording_calibration.hpp"
#include "daemon/pcap/recording_model.hpp"

namespace {

using namespace pandarcap;
using nlohmann::json;

constexpr std::string_view kUsage = R"(Usage: pandarcap-inspect [options] FILE

Dumps the fields of every packet in a capture of a Hesai Pandar40P, Pandar64, PandarXT32,
PandarXT16 or PandarQT128, then a summary (model, packets, rejects by reason, frames, points per
frame, RPM range, sequence gaps). FILE: pcap or pcapng, either compressed with zstd (.pcap.zst),
or MCAP (its pandar_msgs/msg/PandarPacket messages, recorded with output.mcap_packets = true);
the kind is told by the file's first bytes. The model is named by the recording's first packets
(as pandarcapd --replay names it), or by --sensor-model.

Per packet: the first and last block's azimuth, motor speed, µs, return mode, factory byte, date
and time, UDP sequence ("-" when absent); the Pandar40P's tail status (sid, svalue), the
PandarQT128's mode flag and functional-safety state (fs); HIGH-TEMP when the flag is set.

Options:
  --json                 one JSON object: {"packets": [...], "frames": [...], "summary": {...}}
                         (the summary's "model": the model's name, e.g. "PandarXT32")
  --summary              print only the summary (no per-packet lines)
  --sensor-model NAME    the model to decode as: auto (default: the recording's packets name it),
                         pandar40p, pandar64, pandarxt32, pandarxt16, pandarqt128 (any case);
                         another model's packets are then rejected as wrong_model
  --calibration FILE     angle-correction CSV for the model (default: the recording's own, its
                         NAME.calibration.csv sidecar or an MCAP file's attachment, else the
                         model's nominal table)
  --port N               only UDP datagrams to destination port N (default: any port; an
                         MCAP file's packets have no ports: not applied)
  --cut-angle DEG        frame cut angle in degrees (default 0)
  --min-range M          drop points closer than M metres (default 0.3)
  --max-range M          drop points farther than M metres (default 200)
  --dual-return-distance-threshold M
                         merge dual echoes closer than M metres (default 0.1)
  --firing-time-correction
                         correct each channel's azimuth for its firing time (default off)
  --png FILE             also draw the largest complete frame (else the largest) seen from
                         above as a PNG: azimuth 0 (+y) up, +x right, the sensor at the centre
                         with its axes (+x red, +y green), a grid line every 5 m
  --png-colour C         colour the points by height (default) or intensity
  --png-range M          half the width of the picture, metres (default 30)
  --png-size PX          the picture's width and height in pixels (default 800)
  -h, --help             this text

Exit status: 0 the capture was read whole, 1 it is not whole: damaged (capture_status
"error", or "end" with "damage" saying what was read over), cut short ("truncated"), or with
records whose headers are damaged ("malformed"): what was read is summarised, 2 the capture or
calibration cannot be used, 64 bad command line.
)";

struct Options {
  std::string file;
  bool json_output = false;
  bool summary_only = false;
  std::optional<std::string> calibration;
  std::optional<SensorModelId> model;  // --sensor-model; none: "auto"
  std::optional<std::uint16_t> port;
  StreamDecoderConfig decode;
  std::optional<std::string> png;
  TopDownOptions top_down;
};

// The options pandarcapd shares, which set the same configuration keys there: their types and
// ranges are the configuration's (config/command_line.hpp), so both decode a capture alike.
constexpr std::array<std::string_view, 7> kDecodeOptions{"--sensor-model",
                                                         "--calibration",
                                                         "--cut-angle",
                                                         "--min-range",
                                                         "--max-range",
                                                         "--dual-return-distance-threshold",
                                                         "--firing-time-correction"};

Options parse_options(int argc, char** argv) {
  Options options;
  CliArgs args(argc, argv, kUsage);
  DaemonConfig config;  // the defaults, then the decode options given
  while (args.more()) {
    const std::string_view arg = args.next();
    if (arg == "--json") {
      options.json_output = true;
    } else if (arg == "--summary") {
      options.summary_only = true;
    } else if (arg == "--png") {
      options.png = std::string(args.value(arg));
    } else if (arg == "--png-colour" || arg == "--png-color") {
      const std::string_view colour = args.value(arg);
      if (colour == "height") {
        options.top_down.colour = TopDownOptions::Colour::kHeight;
      } else if (colour == "intensity") {
        options.top_down.colour = TopDownOptions::Colour::kIntensity;
      } else {
        args.usage_error(fmt::format("{}: \"{}\" is not one of height, intensity", arg, colour));
      }
    } else if (arg == "--png-range") {
      options.top_down.half_width_m = args.number(arg, 1, 250);
    } else if (arg == "--png-size") {
      options.top_down.size_px = static_cast<int>(args.integer(arg, 64, 8192));
    } else if (arg == "--port") {
      options.port = static_cast<std::uint16_t>(args.integer(arg, 1, 65535));
    } else if (std::find(kDecodeOptions.begin(), kDecodeOptions.end(), arg) !=
               kDecodeOptions.end()) {
      const KeyOption& key = *find_key_option(arg);
      const std::string text(key.flag ? "true" : args.value(arg));
      if (const auto problem = key_option_problem(key, text)) args.usage_error(*problem);
      set_config_value(config, key.key, text, "command line");
    } else if (!arg.empty() && arg[0] == '-') {
      args.unknown_option(arg);
    } else if (options.file.empty()) {
      options.file = arg;
    } else {
      args.usage_error(fmt::format("unexpected argument '{}'", arg));
    }
  }
  if (options.file.empty()) args.usage_error("no capture file given");
  try {
    validate_config(config, "command line");  // --min-range below --max-range
  } catch (const ConfigError& error) {
    args.usage_error(error.what());
  }
  options.decode = stream_decoder_config(config);
  if (!config.sensor.calibration_file.empty()) options.calibration = config.sensor.calibration_file;
  options.model = parse_sensor_model(config.sensor.model);  // checked: a model's name or "auto"
  return options;
}

json frame_json(const FrameInfo& info) {
  return {{"sequence", info.sequence},
          {"points", info.points},
          {"packets", info.packets},
          {"rpm", info.rpm},
          {"start_ns", info.start_ns},
          {"end_ns", info.end_ns},
          {"partial", info.partial},
          {"time_valid", info.time_valid},
          {"return_mode", to_string(info.return_mode)}};
}

std::string_view status_name(CaptureStatus status) {
  switch (status) {
    case CaptureStatus::kEnd:
      return "end";
    case CaptureStatus::kTruncated:
      return "truncated";
    case CaptureStatus::kError:
      return "error";
    case CaptureStatus::kRecord:
      break;
  }
  return "reading";
}

std::string_view format_name(CaptureFormat format) {
  switch (format) {
    case CaptureFormat::kPcapZstd:
      return "pcap.zst";
    case CaptureFormat::kMcap:
      return "mcap";
    case CaptureFormat::kPcap:
      break;
  }
  return "pcap";
}

struct ChosenModel {
  SensorModelId model = SensorModelId::kPandar40P;
  // "sensor-model", "packets", "file" (no packet names one; an MCAP file's sensor_model does),
  // "default" (nothing names one)
  std::string_view source;
};

// --sensor-model, else the model the recording's first packets name (recording_model(), as the
// replay's "auto" does), else the Pandar40P, said on stderr. An unsupported Hesai model is an
// error (exit 2): its packets would only be rejected.
ChosenModel choose_model(const Options& options) {
  if (options.model) return {*options.model, "sensor-model"};
  const std::optional<RecordingModel> found = recording_model(options.file, options.port);
  if (!found) {
    std::fprintf(stderr,
                 "pandarcap-inspect: no packet of %s names a model pandarcap knows: read as the "
                 "Pandar40P (give --sensor-model NAME)\n",
                 options.file.c_str());
    return {SensorModelId::kPandar40P, "default"};
  }
  if (found->detected.kind == DetectionKind::kUnsupported) {
    throw std::runtime_error(fmt::format(
        "{}: its packets are a Hesai {}, which pandarcap does not decode (it decodes the "
        "Pandar40P, Pandar64, PandarXT32, PandarXT16 and PandarQT128)",
        options.file, found->detected.unsupported_name));
  }
  if (found->from_file) return {found->detected.model, "file"};
  if (found->named && *found->named != found->detected.model) {
    std::fprintf(stderr, "pandarcap-inspect: %s names %s, its packets are a %s: read as a %s\n",
                 options.file.c_str(), std::string(display_name(*found->named)).c_str(),
                 std::string(display_name(found->detected.model)).c_str(),
                 std::string(display_name(found->detected.model)).c_str());
  }
  return {found->detected.model, "packets"};
}

// A frame arena large enough for a revolution of `model` at its slowest speed in dual return,
// with 5 % to spare (the daemon's arena_points rule), and never less than the 40P's default.
std::size_t frame_capacity_points(SensorModelId model) {
  return with_model(model, []<class M>(std::type_identity<M>) {
    const int slowest = *std::min_element(M::kSupportedRpms.begin(), M::kSupportedRpms.end());
    const double need =
        std::ceil(M::packets_per_revolution(2, slowest) * M::kMaxPointsPerPacket * 1.05);
    return std::max(kDefaultFrameCapacityPoints, static_cast<std::size_t>(need));
  });
}

int run(const Options& options) {
  const ChosenModel chosen = choose_model(options);
  const SensorModelId model = chosen.model;
  // --calibration, else the recording's own (its sidecar, an MCAP file's attachment), else the
  // model's nominal table: as the replay takes it.
  Calibration calibration = Calibration::nominal(model);
  std::string calibration_source = "nominal";
  if (options.calibration) {
    calibration = load_calibration(*options.calibration, model);
    calibration_source = "file";
  } else {
    std::string looked_for;
    if (std::optional<Calibration> own = recording_calibration(options.file, looked_for, model)) {
      calibration = std::move(*own);
      calibration_source = "recording";
    } else {
      std::fprintf(stderr,
                   "pandarcap-inspect: the recording carries no calibration (looked for %s): the "
                   "nominal %s table is used; give the sensor's with --calibration FILE\n",
                   looked_for.c_str(), std::string(display_name(model)).c_str());
    }
  }
  CaptureReader reader(options.file, CaptureReader::Options{options.port});
  if (options.port && !reader.has_endpoints()) {
    std::fprintf(stderr,
                 "pandarcap-inspect: %s: an MCAP file's packets have no ports: --port %u "
                 "is not applied\n",
                 options.file.c_str(), unsigned{*options.port});
  }

  json frames = json::array();
  json points_per_complete_frame = json::array();
  json packets_per_frame = json::array();
  // The frame --png draws: the largest complete one, else the largest.
  std::vector<Point> picture;
  bool picture_complete = false;
  FrameCollector collector(3, frame_capacity_points(model), [&](const Frame& frame) {
    frames.push_back(frame_json(frame.info));
    const bool complete = !frame.info.partial;
    if (options.png && ((complete && !picture_complete) ||
                        (complete == picture_complete && frame.size > picture.size()))) {
      picture.assign(frame.used().begin(), frame.used().end());
      picture_complete = complete;
    }
    if (!frame.info.partial) points_per_complete_frame.push_back(frame.info.points);
    packets_per_frame.push_back(frame.info.packets);
  });
  AnyStreamDecoder decoder(model, calibration, options.decode, collector);

  const bool per_packet = !options.summary_only;
  if (per_packet && !options.json_output) {
    fmt::print("{}\n", packet_heading(model));
  }
  json packets = json::array();
  CaptureRecord record;
  CaptureStatus status;
  std::uint64_t index = 0;
  std::uint64_t snapped = 0;
  while ((status = reader.next(record)) == CaptureStatus::kRecord) {
    if (record.snapped) ++snapped;
    // A record the file holds only part of is not the packet the sensor sent, even when the part
    // has a valid length: rejected as bad_length (an empty payload), exactly as the daemon does.
    const RejectReason reason =
        decoder.process(record.snapped ? std::span<const std::uint8_t>() : record.payload);
    if (per_packet) {
      json p = packet_json(model, index, record, reason, reader.has_endpoints());
      if (options.json_output) {
        packets.push_back(std::move(p));
      } else {
        fmt::print("{}\n", packet_line(model, p));
      }
    }
    ++index;
  }
  decoder.flush();

  const StreamStats& s = decoder.stats();
  const SequenceStats& seq = decoder.sequence();
  const AssemblerStats& fs = decoder.frames();
  json rejects = json::object();
  for (std::size_t r = 1; r < kRejectReasonCount; ++r) {
    rejects[std::string(to_string(static_cast<RejectReason>(r)))] = s.rejects[r];
  }
  json filtered = json::object();
  for (std::size_t r = 0; r < kFilterReasonCount; ++r) {
    filtered[std::string(to_string(static_cast<FilterReason>(r)))] = s.filtered.by_reason[r];
  }
  const CaptureStats& cs = reader.stats();
  json summary = {
      {"file", options.file},
      {"capture_status", status_name(status)},
      {"capture_error", reader.error()},
      {"capture_format", format_name(reader.format())},
      {"model", display_name(model)},
      {"model_source", chosen.source},
      {"calibration", calibration.source},
      {"calibration_source", calibration_source},
      {"packets", s.packets},
      {"accepted", s.accepted},
      {"rejected", s.rejected()},
      {"rejects", rejects},
      {"rpm_min", s.rpm_min},
      {"rpm_max", s.rpm_max},
      {"return_mode", s.return_mode ? json(to_string(*s.return_mode)) : json(nullptr)},
      {"return_mode_changes", s.return_mode_changes},
      {"sequence_present", s.sequence_packets > 0},
      {"sequence_gaps", seq.gaps},
      {"sequence_lost", seq.lost},
      {"sequence_duplicates", seq.duplicates},
      {"sequence_reordered", seq.reordered},
      {"sequence_resets", seq.resets},
      {"bad_date", s.bad_date},
      {"bad_microseconds", s.bad_microseconds},
      {"static_timestamps", s.static_timestamps},
      {"backward_timestamps", s.backward_timestamps},
      {"timestamp_jumps", s.timestamp_jumps},
      {"high_temperature_packets", s.high_temperature},
      {"points", s.points},
      {"filtered", filtered},
      {"frames_complete", fs.frames_complete},
      {"frames_partial", fs.frames_partial},
      {"frames_dropped", fs.frames_dropped},
      {"points_per_complete_frame", points_per_complete_frame},
      {"packets_per_frame", packets_per_frame},
      {"discontinuities", fs.discontinuities},
      {"points_late", fs.points_late},
      {"capture",
       {{"records", cs.records},
        {"udp_datagrams", cs.udp_datagrams},
        {"ipv6_datagrams", cs.ipv6_datagrams},
        {"port_filtered", cs.port_filtered},
        {"skipped", cs.skipped()},
        {"non_ip", cs.non_ip},
        {"non_udp", cs.non_udp},
        {"ip_fragments", cs.ip_fragments},
        {"malformed", cs.malformed},
        {"snapped", snapped},
        {"chunks_skipped", cs.chunks_skipped},
        {"packets_skipped", cs.packets_skipped},
        {"records_damaged", cs.records_damaged}}},
      {"damage", reader.first_damage()},
  };

  if (options.png) {
    write_png(*options.png, render_top_down(picture, options.top_down));
    if (!options.json_output) {
      fmt::print("drew a {} frame of {} points from above into {}\n",
                 picture_complete ? "complete" : "partial", picture.size(), *options.png);
    }
  }

  if (options.json_output) {
    json out = {{"summary", summary}, {"frames", frames}};
    if (per_packet) out["packets"] = std::move(packets);
    fmt::print("{}\n", out.dump(2));
  } else {
    fmt::print("\nsummary of {} ({}){}\n", options.file, status_name(status),
               reader.error().empty() ? "" : ": " + reader.error());
    fmt::print("  model {} ({})\n", display_name(model),
               chosen.source == "packets"        ? "named by its packets"
               : chosen.source == "sensor-model" ? "--sensor-model"
               : chosen.source == "file"         ? "no packet names one; the file's sensor_model"
                                                 : "nothing names one");
    fmt::print("  packets {}  accepted {}  rejected {}", s.packets, s.accepted, s.rejected());
    for (auto& [name, count] : rejects.items()) {
      if (count.get<std::uint64_t>() > 0) fmt::print("  {} {}", name, count.get<std::uint64_t>());
    }
    fmt::print("\n  return mode {}  rpm {}..{}  sequence {}", summary["return_mode"].dump(),
               s.rpm_min, s.rpm_max, s.sequence_packets > 0 ? "present" : "absent");
    if (s.sequence_packets > 0) fmt::print(" (gaps {}, lost {})", seq.gaps, seq.lost);
    fmt::print("\n  frames complete {}  partial {}  points per complete frame {}\n",
               fs.frames_complete, fs.frames_partial, points_per_complete_frame.dump());
    fmt::print("  packets per frame {}\n  calibration {}\n", packets_per_frame.dump(),
               calibration.source);
    // What the file held besides the packets above, so that "packets 0" is never unexplained.
    fmt::print(
        "  records {}  UDP datagrams {} (IPv6 {})  other ports {}  skipped {} (not IP {}, not UDP "
        "{}, IP fragments {}, malformed {})\n",
        cs.records, cs.udp_datagrams, cs.ipv6_datagrams, cs.port_filtered, cs.skipped(), cs.non_ip,
        cs.non_udp, cs.ip_fragments, cs.malformed);
    if (!reader.first_damage().empty()) {
      fmt::print("  damaged: {} ({} chunks skipped, {} packets in them; {} damaged lengths)\n",
                 reader.first_damage(), cs.chunks_skipped, cs.packets_skipped, cs.records_damaged);
    }
  }
  // Not whole: damaged (stopped, or read over), cut short, or records with damaged headers.
  const bool whole =
      status == CaptureStatus::kEnd && reader.first_damage().empty() && cs.malformed == 0;
  if (!whole) {
    const std::string& why = !reader.error().empty()          ? reader.error()
                             : !reader.first_damage().empty() ? reader.first_damage()
                                                              : std::string();
    std::fprintf(
        stderr, "pandarcap-inspect: %s is not whole: %s\n", options.file.c_str(),
        why.empty() ? "records with damaged headers skipped (see malformed)" : why.c_str());
  }
  return whole ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  const Options options = parse_options(argc, argv);
  try {
    return run(options);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "pandarcap-inspect: %s\n", e.what());
    return 2;
  }
}
