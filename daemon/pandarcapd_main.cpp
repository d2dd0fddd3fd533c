// pandarcapd: the Pandar40P capture daemon.
//
//   receive thread (recvmmsg) or replay --ring--> decode worker --queue--> writer thread
//   main thread: signals, sd_notify READY/STATUS/WATCHDOG/STOPPING, --duration, shutdown order
//
// Start-up, in dependency order (shutdown is the reverse):
//   1. options and configuration (bad config: the file:line:col message and exit 78)
//   2. logging, the sensor: calibration (sensor.calibration_source), identity, configuration
//   3. memory: ring, frame arenas, raw batches, queues — all of it, once
//   4. outputs prepared (directories writable) and the source opened (socket bound / file open)
//   5. threads started, READY=1
// Exit status: 0 done, 1 runtime failure, 64 usage, 66 capture unreadable, 69 the sensor did not
// give its calibration (calibration_source = "sensor"), 73 outputs cannot be created, 78
// configuration (or calibration file) invalid.
#include <fmt/format.h>
#include <pthread.h>
#include <signal.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>
#include <time.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include <thread>
#include <vector>

#include "config/command_line.hpp"
#include "config/config_loader.hpp"
#include "config/daemon_config.hpp"
#include "core/calibration.hpp"
#include "core/decoder_target.hpp"
#include "core/health_state_log.hpp"
#include "core/packet.hpp"
#include "core/sim/simulated_unit.hpp"
#include "core/sim/synthetic_sensor.hpp"
#include "daemon/cli_args.hpp"
#include "daemon/clocks.hpp"
#include "daemon/daemon_options.hpp"
#include "daemon/decode_worker.hpp"
#include "daemon/output/output_directories.hpp"
#include "daemon/packet_slot.hpp"
#include "daemon/source/packet_source.hpp"
#include "daemon/pcap/capture_reader.hpp"
#include "daemon/pipeline.hpp"
#include "daemon/pipeline_types.hpp"
#include "daemon/ptc/sensor_at_start.hpp"
#include "daemon/ptc/sensor_status_poller.hpp"
#include "daemon/ptc/simulated_ptc_server.hpp"
#include "daemon/source/replay_source.hpp"
#include "daemon/sd_notify.hpp"
#include "daemon/source/simulated_sender.hpp"
#include "daemon/thread_tuning.hpp"
#include "daemon/source/udp_receiver.hpp"
#include "daemon/output/writer.hpp"
#include "ringbuf/spsc_queue.hpp"

namespace {

using namespace pandarcap;

constexpr std::string_view kVersion = PANDARCAP_VERSION;

constexpr std::string_view kUsage =
    R"(Usage: pandarcapd [options]                  live capture from the sensor
       pandarcapd --simulate [options]       live path fed by a built-in simulated sensor
       pandarcapd --replay FILE [options]    process a pcap/pcapng recording

Captures a Hesai Pandar40P: receives its UDP packets, decodes them into frames, and writes
OUTPUT-DIR/frames/*.pcd, OUTPUT-DIR/raw/*.pcap (+ calibration.csv), with --mcap
OUTPUT-DIR/mcap/*.mcap (Foxglove, ros2 bag) and, every second,
OUTPUT-DIR/health/pandarcap.prom and health.jsonl. SIGTERM/SIGINT stop it cleanly, SIGHUP
starts new recording files.

Configuration:
  -c, --config FILE      TOML configuration (see config/pandarcap.toml); without it the
                         defaults apply, and the options below override either
  --check-config         check everything the start checks without network: the configuration,
                         the calibration file, the decoder, and that every output directory is
                         (or can be made) writable by this user; print the result and exit
                         (0, 73 outputs, 78 configuration or calibration)
  --print-config         print the effective configuration as TOML and exit
  --print-calibration    print the angle-correction table in effect (from the sensor, the
                         calibration file or the nominal table, as calibration_source says) as
                         CSV and exit

Sources:
  --simulate             start a simulated sensor that sends over loopback to the daemon's own
                         socket (127.0.0.1, a free port unless --port is given)
  --replay FILE          read packets from a capture file instead of the network; exits when
                         the file is done
  --top-speed            replay as fast as the decoder goes (the default)
  --rate X               replay at X times the recorded pace (1 = real time)
  --duration S           stop after S seconds (live and simulated runs)

Overrides (same names as the configuration keys):
  --output-dir DIR       output.directory (default pandarcap-output)
  --calibration FILE     sensor.calibration_file (default: the nominal Pandar40P table)
  --calibration-source S sensor.calibration_source: auto (default: the sensor over PTC if it
                         answers, else the file, else nominal), sensor, file or nominal
  --ptc-port N           sensor.ptc_port (default 9347); with --simulate: ask this port on
                         127.0.0.1 instead of the simulated sensor's own
  --status-interval S    sensor.status_interval_seconds (default 5): poll the sensor's status
                         (PTP/GPS lock, motor, temperatures) over PTC; 0 = off
  --host-ip IP           sensor.host_ip (default 0.0.0.0)
  --port N               sensor.data_port (default 2368); with --replay: only datagrams to N
  --sensor-ip IP         sensor.sensor_ip: drop (and count) datagrams from other sources
  --cut-angle DEG        sensor.cut_angle (default 0)
  --frame AXES           sensor.frame: hesai (default; the sensor's axes, y at azimuth 0) or ros
                         (REP 103: x forward, y left, z up)
  --pcd-fields LAYOUT    output.pcd_fields: pcl (default: float intensity, PCL's PointXYZI),
                         pandarcap, velodyne (PointXYZIRT) or autoware (nebula's PointXYZIRCAEDT)
  --min-range M          sensor.min_range (default 0.3)
  --max-range M          sensor.max_range (default 200)
  --dual-return-distance-threshold M
                         sensor.dual_return_distance_threshold (default 0.1)
  --firing-time-correction
                         sensor.firing_time_correction = true
  --rpm N                simulated (and expected) motor speed, 600 or 1200
  --return-mode MODE     simulated (and expected) return mode: dual, strongest or last
  --udp-sequence         the simulated sensor appends a UDP sequence number
  --decoder NAME         decoder: auto (default), scalar, sse4, avx2, avx512, neon, sve, sve2
  --mcap                 output.mcap = true: also write MCAP files (PointCloud2 frames, health)
  --mcap-packets         output.mcap_packets = true: every datagram into the MCAP files too
  --mcap-only            output.mcap = true, output.frames = false, output.pcap = false; with
                         --replay FILE this converts a capture to MCAP
  --latency-budget-ms N  latency.budget_ms (default 5): how long a datagram may wait before the
                         receive thread drains the socket; 0 = wake for every datagram
  --log-level LEVEL      trace, debug, info, warn, error, critical, off
  --max-clock-offset S   health.max_sensor_clock_offset_seconds (default 1): a sensor clock
                         further from the host's makes the state degraded; 0 = not checked
                         (replays of recordings from an unsynchronised sensor)
  --allow-root           run even as root (refused otherwise: pandarcapd needs no privilege,
                         and a parser of network packets should not hold one; the systemd unit
                         runs it as the user pandarcap)
  --version              print the version and exit
  -h, --help             this text

Exit status: 0 done, 1 runtime failure, 64 usage error, 66 capture file unreadable,
69 the sensor did not give its calibration (calibration_source = "sensor"), 73 output
directory not writable or in use by another pandarcapd, 77 run as root without --allow-root,
78 invalid configuration or calibration file.
)";

constexpr int kExitUsage = 64;
constexpr int kExitNoInput = 66;
constexpr int kExitUnavailable = 69;
constexpr int kExitCantCreate = 73;
constexpr int kExitNoPermission = 77;
constexpr int kExitConfig = 78;

struct Options {
  std::optional<std::string> config_path;
  bool check_config = false;
  bool print_config = false;
  bool print_calibration = false;
  bool allow_root = false;
  RunSource source;
  std::optional<double> duration_s;
  // Keys set on the command line, applied to the configuration in the order given.
  std::vector<std::pair<std::string_view, std::string>> overrides;
};

Options parse_options(int argc, char** argv) {
  CliArgs args(argc, argv, kUsage);
  Options o;
  bool simulate = false;
  std::optional<std::string> replay;
  while (args.more()) {
    const std::string_view arg = args.next();
    if (arg == "-c" || arg == "--config") {
      o.config_path = std::string(args.value(arg));
    } else if (arg == "--check-config") {
      o.check_config = true;
    } else if (arg == "--print-config") {
      o.print_config = true;
    } else if (arg == "--print-calibration") {
      o.print_calibration = true;
    } else if (arg == "--simulate") {
      simulate = true;
    } else if (arg == "--allow-root") {
      o.allow_root = true;
    } else if (arg == "--replay") {
      replay = std::string(args.value(arg));
    } else if (arg == "--top-speed") {
      o.source.rate.reset();
    } else if (arg == "--rate") {
      o.source.rate = args.number(arg, 0.001, 1000);
    } else if (arg == "--duration") {
      o.duration_s = args.number(arg, 0.1, 1e7);
    } else if (arg == "--udp-sequence") {
      o.source.simulated_udp_sequence = true;
    } else if (arg == "--mcap-only") {
      // Conversion: the frames (and packets, with output.mcap_packets) go to MCAP only.
      o.overrides.emplace_back("output.mcap", "true");
      o.overrides.emplace_back("output.frames", "false");
      o.overrides.emplace_back("output.pcap", "false");
    } else if (const KeyOption* key = find_key_option(arg)) {
      // A configuration key: its type and range are the file's (config/command_line.hpp).
      const std::string text(key->flag ? "true" : args.value(arg));
      if (const auto problem = key_option_problem(*key, text)) args.usage_error(*problem);
      if (arg == "--port") o.source.port_given = true;
      if (arg == "--ptc-port") o.source.ptc_port_given = true;
      if (arg == "--rpm") {
        // Also the simulated sensor's speed; a Pandar40P turns at one of two.
        o.source.simulated_rpm = std::stoi(text);
        if (o.source.simulated_rpm != 600 && o.source.simulated_rpm != 1200) {
          args.usage_error("--rpm takes 600 or 1200");
        }
      }
      if (arg == "--return-mode") {
        // Also the simulated sensor's mode, which must be one a sensor sends ("any" is not).
        const auto mode = return_mode_from_string(text);
        if (!mode) args.usage_error("--return-mode takes dual, strongest or last");
        o.source.simulated_mode = *mode;
      }
      o.overrides.emplace_back(key->key, text);
    } else {
      args.unknown_option(arg);
    }
  }
  if (simulate && replay) args.usage_error("--simulate and --replay exclude each other");
  if (o.source.rate && !replay) args.usage_error("--rate applies to --replay only");
  if (simulate) o.source.kind = RunSource::Kind::kSimulated;
  if (replay) {
    o.source.kind = RunSource::Kind::kReplay;
    o.source.replay_path = *replay;
  }
  return o;
}

void setup_logging(const std::string& level) {
  auto logger = spdlog::stderr_color_mt("pandarcapd");
  // Under systemd, journald timestamps every line itself.
  if (std::getenv("JOURNAL_STREAM") != nullptr) {
    logger->set_pattern("[%l] %v");
  } else {
    logger->set_pattern("%Y-%m-%dT%H:%M:%S.%e [%l] %v");
  }
  logger->set_level(spdlog::level::from_str(level));
  spdlog::set_default_logger(logger);
}

// From the writer's final health in memory, not from health.jsonl: when the disk is full the
// file's last line is an older one, and the summary must say how the run really ended.
void print_summary(const WriterOptions& wo, const HealthSnapshot& h) {
  const std::filesystem::path& dir = wo.output_dir;
  fmt::print("outputs in {}:\n", dir.string());
  if (wo.frames) fmt::print("  frames  {}\n", (dir / "frames").string());
  if (wo.pcap) fmt::print("  raw     {}\n", (dir / "raw").string());
  if (wo.mcap) fmt::print("  mcap    {}\n", (dir / "mcap").string());
  fmt::print("  health  {} and {}\n", wo.prometheus_file.string(),
             (wo.health_dir / "health.jsonl").string());
  const HealthCounters& c = h.counters;
  fmt::print(
      "final health: state {}{}; {} datagrams received, {} accepted, {} rejected, {} foreign, "
      "{} ring overruns, {} kernel drops; frames {} complete, {} partial, {} dropped, {} "
      "fragments, {} written; {} packets recorded; {} write errors\n",
      to_string(h.gauges.state), h.gauges.reason.empty() ? "" : " (" + h.gauges.reason + ")",
      c.datagrams_received, c.packets_accepted, c.packets_rejected, c.foreign_datagrams,
      c.ring_overruns, c.kernel_drops, c.frames_complete, c.frames_partial,
      c.frames_dropped_no_arena, c.frames_fragment, c.frames_written, c.pcap_packets_written,
      c.write_errors);
  if (wo.mcap) {
    fmt::print("mcap: {} messages written, {} not written, {} bytes\n", c.mcap_messages_written,
               c.mcap_messages_not_written, c.mcap_bytes_written);
  }
}

// --check-config: what the start would refuse, short of opening the socket or the capture.
int check_config(const DaemonConfig& config, const std::string& source_name) {
  try {
    // The file the start would read; the sensor is not asked (no network here).
    const SensorSection& s = config.sensor;
    if (s.calibration_source != "nominal" && !s.calibration_file.empty())
      Calibration::load(s.calibration_file);
  } catch (const std::exception& error) {
    std::fprintf(stderr, "pandarcapd: %s\n", error.what());
    return kExitConfig;
  }
  const DecoderChoice decoder = choose_decoder_target(config.decoder);
  if (!decoder.target) {
    std::fprintf(stderr, "pandarcapd: %s: decoder: %s\n", source_name.c_str(),
                 decoder.error.c_str());
    return kExitConfig;
  }
  const std::vector<std::string> problems = output_problems(writer_options(config));
  for (const std::string& problem : problems)
    std::fprintf(stderr, "pandarcapd: %s: outputs: %s\n", source_name.c_str(), problem.c_str());
  if (!problems.empty()) return kExitCantCreate;
  fmt::print("{}: configuration OK\n", source_name);
  return 0;
}

// A start-up step that cannot go on: the exit status and what to say. Thrown by the steps below,
// reported once by run().
struct StartupError {
  int exit_status;
  std::string message;
};

// 1. The configuration: the file, then the command line's keys, checked as a whole.
DaemonConfig load_configuration(const Options& options, const std::string& source_name) {
  try {
    DaemonConfig config;
    if (options.config_path) config = load_config_file(*options.config_path);
    for (const auto& [key, text] : options.overrides)
      set_config_value(config, key, text, source_name);
    validate_config(config, source_name);
    return config;
  } catch (const ConfigError& error) {
    throw StartupError{kExitConfig, error.what()};
  }
}

// 2. Checked before any socket or output file is opened. Reading the configuration and printing
// tables is harmless as root; parsing what arrives from the network is not.
void refuse_root_unless_allowed(const Options& options) {
  if (::geteuid() != 0) return;
  if (!options.allow_root) {
    throw StartupError{
        kExitNoPermission,
        "refusing to run as root: pandarcapd needs no privilege (UDP on any port it is given, "
        "files it owns). Run it as an unprivileged user (the systemd unit uses 'pandarcap'), or "
        "pass --allow-root to accept the risk (containers, CI)"};
  }
  spdlog::warn("running as root (--allow-root)");
}

void log_sensor(const SensorAtStart& sensor, const DaemonConfig& config, const RunSource& source) {
  if (sensor.calibration_source == "nominal") {
    spdlog::warn(
        "calibration: nominal Pandar40P table in use (no sensor answer, no calibration_file); "
        "per-unit elevations differ by up to ~0.45 degrees");
  } else {
    spdlog::info("calibration: {}", sensor.describe());
  }
  if (sensor.settings) {
    const ptc::SensorSettings& s = *sensor.settings;
    spdlog::info("sensor config: {} RPM, clock source {}, destination {}:{}{}", s.spin_rate_rpm,
                 ptc::clock_source_name(s.clock_source), ptc::ipv4_text(s.destination_ip),
                 s.data_port, s.udp_sequence != 0 ? ", UDP sequence on" : "");
    // What the sensor says it does against what this daemon expects: a mismatch found now is
    // an afternoon saved (the simulated sensor sends where the daemon's socket is, whatever
    // its configuration says).
    if (source.kind == RunSource::Kind::kLive && s.data_port != config.sensor.data_port) {
      spdlog::warn("sensor config: the sensor sends to port {}, pandarcapd listens on {}",
                   s.data_port, config.sensor.data_port);
    }
    if (s.spin_rate_rpm != config.sensor.rotation_speed) {
      spdlog::warn("sensor config: the sensor spins at {} RPM, rotation_speed expects {}",
                   s.spin_rate_rpm, config.sensor.rotation_speed);
    }
  }
}

// 2. The sensor: its calibration (by calibration_source), identity and configuration. A
// simulated run first starts the simulated sensor's PTC server (`simulated_ptc`), to be asked as
// a real sensor is.
SensorAtStart learn_sensor(const DaemonConfig& config, const RunSource& source,
                           std::unique_ptr<SimulatedPtcServer>& simulated_ptc,
                           std::optional<PtcClientOptions>& ptc) {
  try {
    if (source.kind == RunSource::Kind::kSimulated && !source.ptc_port_given) {
      simulated_ptc = std::make_unique<SimulatedPtcServer>(
          simulated_unit(source.simulated_rpm, static_cast<std::uint8_t>(source.simulated_mode),
                         source.simulated_udp_sequence, config.sensor.data_port));
    }
    ptc = ptc_client_options(config, source, simulated_ptc ? simulated_ptc->port() : 0);
    return resolve_sensor_at_start(config.sensor.calibration_source, config.sensor.calibration_file,
                                   ptc);
  } catch (const SensorUnavailable& error) {
    throw StartupError{kExitUnavailable, error.what()};
  } catch (const CalibrationError& error) {
    throw StartupError{kExitConfig, error.what()};
  } catch (const std::exception& error) {
    throw StartupError{1, error.what()};
  }
}

// The decoder is chosen once, here; a named target this CPU cannot run is a configuration
// error, not a reason to quietly run another.
DecoderTarget choose_decoder(const DaemonConfig& config) {
  const DecoderChoice choice = choose_decoder_target(config.decoder);
  if (!choice.target) throw StartupError{kExitConfig, choice.error};
  spdlog::info("decoder: {}{}", to_string(*choice.target),
               config.decoder == "auto" ? " (auto)" : "");
  return *choice.target;
}

std::unique_ptr<PacketSource> open_source(const DaemonConfig& config, const RunSource& source) {
  try {
    switch (source.kind) {
      case RunSource::Kind::kReplay:
        return PacketSource::replay(replay_options(config, source));
      case RunSource::Kind::kSimulated:
        return PacketSource::simulated(receiver_options(config, source),
                                       simulated_sensor_config(source, realtime_ns()));
      case RunSource::Kind::kLive:
        break;
    }
    return PacketSource::live(receiver_options(config, source));
  } catch (const CaptureError& error) {
    throw StartupError{kExitNoInput, error.what()};
  } catch (const std::exception& error) {
    throw StartupError{1, error.what()};
  }
}

// One daemon per output directory, claimed before anything in it is touched (crash recovery,
// numbering and retention all assume the files are this process's or a finished run's).
std::unique_ptr<OutputDirectoryLock> claim_outputs(const std::filesystem::path& directory) {
  try {
    return std::make_unique<OutputDirectoryLock>(directory);
  } catch (const OutputDirectoryBusy& error) {
    throw StartupError{kExitCantCreate, error.what()};
  } catch (const std::exception& error) {
    throw StartupError{kExitCantCreate, fmt::format("outputs: {}", error.what())};
  }
}

// Signals are blocked before the threads start, so every thread inherits the mask and only the
// main thread takes them, synchronously, with sigtimedwait.
sigset_t block_signals() {
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGHUP);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);
  return signals;
}

// The main thread while the pipeline runs: signals, --duration, the end of a replay, STATUS and
// WATCHDOG. Returns when the daemon should stop.
void supervise(Pipeline& pipe, const sigset_t& signals, std::optional<double> duration_s) {
  const auto start = std::chrono::steady_clock::now();
  const auto watchdog = systemd::watchdog_interval();
  const auto tick = std::chrono::milliseconds(100);
  auto next_watchdog = start;
  std::uint64_t seen[3] = {~0ull, ~0ull, ~0ull};
  HealthStateLog state_log;
  for (;;) {
    const timespec timeout{0, std::chrono::nanoseconds(tick).count()};
    const int signal = sigtimedwait(&signals, nullptr, &timeout);
    if (signal == SIGTERM || signal == SIGINT) {
      spdlog::info("{}: stopping", signal == SIGTERM ? "SIGTERM" : "SIGINT");
      return;
    }
    if (signal == SIGHUP) pipe.rotate_generation.fetch_add(1, std::memory_order_relaxed);
    const auto now = std::chrono::steady_clock::now();  // one clock read a tick
    if (duration_s && now - start >= std::chrono::duration<double>(*duration_s)) {
      spdlog::info("{} s elapsed: stopping", *duration_s);
      return;
    }
    if (pipe.source_done.load(std::memory_order_acquire)) return;  // replay finished
    const double since_start = std::chrono::duration<double>(now - start).count();
    StatusLine status;
    while (pipe.status.try_pop(status)) {
      systemd::status(status.text);
      if (auto line = state_log.update(status.state, status.reason, since_start)) {
        if (line->warning) {
          spdlog::warn("{}", line->text);
        } else {
          spdlog::info("{}", line->text);
        }
      }
    }
    if (watchdog && now >= next_watchdog) {
      // Only while all three loops are making progress (each bumps its counter even when idle).
      const std::uint64_t beats[3] = {pipe.heartbeats.receive.load(), pipe.heartbeats.decode.load(),
                                      pipe.heartbeats.writer.load()};
      if (beats[0] != seen[0] && beats[1] != seen[1] && beats[2] != seen[2]) {
        systemd::watchdog();
        std::copy(std::begin(beats), std::end(beats), std::begin(seen));
      }
      next_watchdog = now + *watchdog / 2;
    }
  }
}

// How a replay ended: 1 when the file turned out corrupt part-way, else 0.
int report_replay(const PacketSource& source, const RunSource& run_source) {
  if (!source.replayed()) return 0;
  const ReplayResult& result = source.replay_result();
  const auto& capture = result.capture;
  spdlog::info(
      "replay: {} records, {} UDP datagrams ({} other ports, {} non-IPv4, {} non-UDP, "
      "{} fragments, {} malformed)",
      capture.records, capture.udp_datagrams, capture.port_filtered, capture.non_ipv4,
      capture.non_udp, capture.ip_fragments, capture.malformed);
  if (result.status == CaptureStatus::kTruncated) {
    spdlog::warn("{}: the file ends in the middle of a record (cut off while recording)",
                 run_source.replay_path);
  } else if (result.status == CaptureStatus::kError) {
    spdlog::error("{}: {}", run_source.replay_path, result.error);
    return 1;
  }
  return 0;
}

std::string describe(const RunSource& source) {
  switch (source.kind) {
    case RunSource::Kind::kSimulated:
      return "simulated sensor";
    case RunSource::Kind::kReplay:
      return "replay of " + source.replay_path;
    case RunSource::Kind::kLive:
      break;
  }
  return "live capture";
}

// The daemon's life, in order; shutdown is the reverse (PipelineThreads).
int run(const Options& options) {
  const std::string source_name = options.config_path.value_or("command line");
  const DaemonConfig config = load_configuration(options, source_name);
  if (options.check_config) return check_config(config, source_name);
  if (options.print_config) {
    fmt::print("{}", to_toml(config));
    return 0;
  }

  setup_logging(config.log_level);
  if (!options.print_calibration) {
    spdlog::info("pandarcapd {} starting ({})", kVersion, describe(options.source));
  }
  // Signals are blocked before the first thread starts (the simulated sensor's PTC server is
  // one): a SIGTERM delivered to a thread that has it unblocked would kill the process instead
  // of reaching supervise().
  const sigset_t signals = block_signals();
  std::unique_ptr<SimulatedPtcServer> simulated_ptc;  // outlives every thread that asks it
  std::optional<PtcClientOptions> ptc;
  const SensorAtStart sensor = learn_sensor(config, options.source, simulated_ptc, ptc);
  const Calibration& calibration = sensor.calibration;
  if (options.print_calibration) {
    fmt::print("{}", calibration.to_csv());
    return 0;
  }
  refuse_root_unless_allowed(options);
  log_sensor(sensor, config, options.source);
  const DecoderTarget decoder = choose_decoder(config);

  Pipeline pipe(config);  // all the memory, now
  spdlog::info(
      "memory: ring {} slots x {} B, {} frame arenas x {} points, {} raw batches x {} "
      "packets",
      config.ring.slots, sizeof(PacketSlot), config.arenas.count, config.arenas.points_per_frame,
      Pipeline::raw_batches(config), config.arenas.packets_per_frame);

  const std::unique_ptr<PacketSource> source = open_source(config, options.source);
  WriterOptions wo = writer_options(config);
  wo.decoder = std::string(to_string(decoder));
  wo.calibration_csv = calibration.to_csv();
  wo.sensor_identity = SensorIdentity{sensor.inventory ? sensor.inventory->serial : "",
                                      sensor.inventory ? sensor.inventory->sensor_firmware : "",
                                      sensor.calibration_source};
  wo.sensor_json = sensor.to_json();
  wo.status_polled = status_polled(config, options.source, ptc);
  wo.status_interval_seconds = config.sensor.status_interval_seconds;
  pipe.sensor_status.requests.store(sensor.ptc_requests);
  pipe.sensor_status.errors.store(sensor.ptc_errors);
  wo.mcap_replay_time = options.source.kind == RunSource::Kind::kReplay;
  const auto lock = claim_outputs(config.output.directory);
  Writer writer(wo, pipe.to_writer, pipe.free_arenas, pipe.free_raw, pipe.receive, pipe.live,
                pipe.sensor_status);
  try {
    writer.prepare();
  } catch (const std::exception& error) {
    throw StartupError{kExitCantCreate, fmt::format("outputs: {}", error.what())};
  }
  DecodeWorker worker(calibration, decode_worker_options(config, decoder, options.source),
                      pipe.ring, pipe.to_writer, pipe.free_arenas, pipe.free_raw);

  const ThreadsSection& placement = config.threads;
  std::atomic<bool> stop_simulator{false};
  PipelineThreads threads;
  threads.start(
      "pc-writer",
      [&] {
        place_this_thread("writer", {placement.writer_cpu, placement.writer_priority});
      },
      [&] { writer.run(pipe.heartbeats.writer, pipe.rotate_generation, pipe.status); });
  threads.start(
      "pc-decode",
      [&] {
        place_this_thread("decode", {placement.decode_cpu, placement.decode_priority});
      },
      [&] { worker.run(pipe.source_done, pipe.heartbeats.decode, pipe.live); });
  threads.start(
      source->thread_name(),
      [&] {
        place_this_thread("receive", {placement.receive_cpu, placement.receive_priority});
      },
      [&] {
        source->run(pipe.ring, pipe.stop_source, pipe.receive, pipe.heartbeats.receive,
                    pipe.source_done);
      },
      [&] { pipe.stop_source.store(true, std::memory_order_relaxed); });
  if (source->simulated()) {
    threads.start(
        "pc-simsensor", {}, [&] { source->run_simulator(stop_simulator); },
        [&] { stop_simulator.store(true, std::memory_order_relaxed); });
  }
  std::optional<SensorStatusPoller> status_poller;
  if (wo.status_polled) {
    const auto interval = std::chrono::milliseconds(
        static_cast<std::int64_t>(config.sensor.status_interval_seconds * 1000));
    status_poller.emplace(
        *ptc, interval, pipe.sensor_status,
        sensor.settings ? std::optional(sensor.settings->clock_source) : std::nullopt);
    spdlog::info("sensor status: asking {}:{} every {} s", ptc->address, ptc->port,
                 config.sensor.status_interval_seconds);
    threads.start(
        "pc-sensorstat", {}, [&] { status_poller->run(); }, [&] { status_poller->stop(); });
  }
  if (config.threads.lock_memory) lock_all_memory();
  systemd::ready();
  spdlog::info("ready: writing to {}", config.output.directory);

  supervise(pipe, signals, options.duration_s);

  systemd::stopping();
  threads.stop_all();  // the decoder drains the ring, the writer finishes every file
  const int status = report_replay(*source, options.source);
  print_summary(wo, writer.final_health());
  return status;
}

}  // namespace

int main(int argc, char** argv) {
  // A file-size limit (systemd's LimitFSIZE=, ulimit -f) must fail the one write with EFBIG,
  // counted like a full disk, not kill the daemon with SIGXFSZ.
  std::signal(SIGXFSZ, SIG_IGN);
  const Options options = parse_options(argc, argv);
  try {
    return run(options);
  } catch (const StartupError& error) {
    // Before logging is set up (the configuration), plain stderr; after it, the log.
    if (spdlog::get("pandarcapd") != nullptr) {
      spdlog::critical("{}", error.message);
    } else {
      std::fprintf(stderr, "pandarcapd: %s\n", error.message.c_str());
    }
    return error.exit_status;
  } catch (const std::exception& error) {
    std::fprintf(stderr, "pandarcapd: %s\n", error.what());
    return 1;
  }
}
