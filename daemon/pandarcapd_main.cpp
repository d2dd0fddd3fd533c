// pandarcapd: the Pandar40P capture daemon.
//
//   receive thread (recvmmsg) or replay --ring--> decode worker --queue--> writer thread
//   main thread: signals, sd_notify READY/STATUS/WATCHDOG/STOPPING, --duration, shutdown order
//
// Start-up, in dependency order (shutdown is the reverse):
//   1. options and configuration (bad config: the file:line:col message and exit 78)
//   2. logging, calibration
//   3. memory: ring, frame arenas, raw batches, queues — all of it, once
//   4. outputs prepared (directories writable) and the source opened (socket bound / file open)
//   5. threads started, READY=1
// Exit status: 0 done, 1 runtime failure, 64 usage, 66 capture unreadable, 73 outputs cannot be
// created, 78 configuration (or calibration file) invalid.
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

#include "config/config_loader.hpp"
#include "config/daemon_config.hpp"
#include "core/calibration.hpp"
#include "core/decoder_target.hpp"
#include "core/packet.hpp"
#include "core/sim/synthetic_sensor.hpp"
#include "daemon/cli_args.hpp"
#include "daemon/clocks.hpp"
#include "daemon/decode_worker.hpp"
#include "daemon/output_directories.hpp"
#include "daemon/packet_slot.hpp"
#include "daemon/pcap/capture_reader.hpp"
#include "daemon/pipeline_types.hpp"
#include "daemon/replay_source.hpp"
#include "daemon/sd_notify.hpp"
#include "daemon/simulated_sender.hpp"
#include "daemon/thread_tuning.hpp"
#include "daemon/udp_receiver.hpp"
#include "daemon/writer.hpp"
#include "ringbuf/spsc_queue.hpp"

namespace {

// Linux thread names are at most 15 characters.
void name_this_thread(const char* name) {
  pthread_setname_np(pthread_self(), name);
}

using namespace pandarcap;

constexpr std::string_view kVersion = PANDARCAP_VERSION;

constexpr std::string_view kUsage =
    R"(Usage: pandarcapd [options]                  live capture from the sensor
       pandarcapd --simulate [options]       live path fed by a built-in simulated sensor
       pandarcapd --replay FILE [options]    process a pcap/pcapng recording

Captures a Hesai Pandar40P: receives its UDP packets, decodes them into frames, and writes
OUTPUT-DIR/frames/*.pcd, OUTPUT-DIR/raw/*.pcap (+ calibration.csv) and, every second,
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
  --print-calibration    print the angle-correction table in effect (the calibration file, or
                         the nominal Pandar40P table) as CSV and exit

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
  --host-ip IP           sensor.host_ip (default 0.0.0.0)
  --port N               sensor.data_port (default 2368); with --replay: only datagrams to N
  --sensor-ip IP         sensor.sensor_ip: drop (and count) datagrams from other sources
  --cut-angle DEG        sensor.cut_angle (default 0)
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
  --latency-budget-ms N  latency.budget_ms (default 5): how long a datagram may wait before the
                         receive thread drains the socket; 0 = wake for every datagram
  --log-level LEVEL      trace, debug, info, warn, error, critical, off
  --allow-root           run even as root (refused otherwise: pandarcapd needs no privilege,
                         and a parser of network packets should not hold one; the systemd unit
                         runs it as the user pandarcap)
  --version              print the version and exit
  -h, --help             this text

Exit status: 0 done, 1 runtime failure, 64 usage error, 66 capture file unreadable,
73 output directory not writable or in use by another pandarcapd, 77 run as root without
--allow-root, 78 invalid configuration or calibration file.
)";

constexpr int kExitUsage = 64;
constexpr int kExitNoInput = 66;
constexpr int kExitCantCreate = 73;
constexpr int kExitNoPermission = 77;
constexpr int kExitConfig = 78;

struct Options {
  std::optional<std::string> config_path;
  bool check_config = false;
  bool print_config = false;
  bool print_calibration = false;
  bool simulate = false;
  bool allow_root = false;
  std::optional<std::string> replay;
  std::optional<double> rate;
  std::optional<double> duration_s;
  bool port_given = false;
  bool udp_sequence = false;
  ReturnMode simulated_mode = ReturnMode::kDual;
  int simulated_rpm = 600;
  // Overrides, applied to the configuration in the order given.
  std::vector<std::function<void(DaemonConfig&)>> overrides;
};

Options parse_options(int argc, char** argv) {
  CliArgs args(argc, argv, kUsage);
  Options o;
  const auto set = [&](auto apply) { o.overrides.emplace_back(apply); };
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
      o.simulate = true;
    } else if (arg == "--allow-root") {
      o.allow_root = true;
    } else if (arg == "--replay") {
      o.replay = std::string(args.value(arg));
    } else if (arg == "--top-speed") {
      o.rate.reset();
    } else if (arg == "--rate") {
      o.rate = args.number(arg, 0.001, 1000);
    } else if (arg == "--duration") {
      o.duration_s = args.number(arg, 0.1, 1e7);
    } else if (arg == "--output-dir") {
      const std::string dir(args.value(arg));
      set([dir](DaemonConfig& c) { c.output.directory = dir; });
    } else if (arg == "--calibration") {
      const std::string file(args.value(arg));
      set([file](DaemonConfig& c) { c.sensor.calibration_file = file; });
    } else if (arg == "--host-ip") {
      const std::string ip(args.value(arg));
      set([ip](DaemonConfig& c) { c.sensor.host_ip = ip; });
    } else if (arg == "--port") {
      const auto port = static_cast<std::uint16_t>(args.integer(arg, 1, 65535));
      o.port_given = true;
      set([port](DaemonConfig& c) { c.sensor.data_port = port; });
    } else if (arg == "--sensor-ip") {
      const std::string ip(args.value(arg));
      set([ip](DaemonConfig& c) { c.sensor.sensor_ip = ip; });
    } else if (arg == "--cut-angle") {
      const double v = args.number(arg, 0, 359.99);
      set([v](DaemonConfig& c) { c.sensor.cut_angle = v; });
    } else if (arg == "--min-range") {
      const double v = args.number(arg, 0, 1000);
      set([v](DaemonConfig& c) { c.sensor.min_range = v; });
    } else if (arg == "--max-range") {
      const double v = args.number(arg, 0, 1000);
      set([v](DaemonConfig& c) { c.sensor.max_range = v; });
    } else if (arg == "--dual-return-distance-threshold") {
      const double v = args.number(arg, 0, 10);
      set([v](DaemonConfig& c) { c.sensor.dual_return_distance_threshold = v; });
    } else if (arg == "--firing-time-correction") {
      set([](DaemonConfig& c) { c.sensor.firing_time_correction = true; });
    } else if (arg == "--rpm") {
      const auto rpm = static_cast<int>(args.integer(arg, 600, 1200));
      if (rpm != 600 && rpm != 1200) args.usage_error("--rpm takes 600 or 1200");
      o.simulated_rpm = rpm;
      set([rpm](DaemonConfig& c) { c.sensor.rotation_speed = rpm; });
    } else if (arg == "--return-mode") {
      const std::string_view name = args.value(arg);
      const auto mode = return_mode_from_string(name);
      if (!mode) args.usage_error("--return-mode takes dual, strongest or last");
      o.simulated_mode = *mode;
      const std::string text(name);
      set([text](DaemonConfig& c) { c.sensor.return_mode = text; });
    } else if (arg == "--udp-sequence") {
      o.udp_sequence = true;
    } else if (arg == "--decoder") {
      const std::string name(args.value(arg));
      set([name](DaemonConfig& c) { c.decoder = name; });
    } else if (arg == "--latency-budget-ms") {
      const auto ms = static_cast<std::uint32_t>(args.integer(arg, 0, 1000));
      set([ms](DaemonConfig& c) { c.latency.budget_ms = ms; });
    } else if (arg == "--log-level") {
      const std::string level(args.value(arg));
      set([level](DaemonConfig& c) { c.log_level = level; });
    } else {
      args.usage_error(fmt::format("unknown option '{}'", arg));
    }
  }
  if (o.simulate && o.replay) args.usage_error("--simulate and --replay exclude each other");
  if (o.rate && !o.replay) args.usage_error("--rate applies to --replay only");
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

// The fixed memory of the pipeline, allocated before any thread starts.
struct Pipeline {
  explicit Pipeline(const DaemonConfig& c)
      : ring(c.ring.slots),
        free_arenas(round_up(c.arenas.count)),
        free_raw(round_up(raw_batches(c))),
        to_writer(round_up(c.arenas.count + raw_batches(c) + 16)),
        status(4) {
    for (std::uint32_t i = 0; i < c.arenas.count; ++i) {
      arenas.push_back(std::make_unique<FrameArena>(c.arenas.points_per_frame));
      free_arenas.try_push(arenas.back().get());
    }
    for (std::uint32_t i = 0; i < raw_batches(c); ++i) {
      raw.push_back(std::make_unique<RawBatch>(c.arenas.packets_per_frame));
      free_raw.try_push(raw.back().get());
    }
  }
  // As many raw batches as arenas: the recording may fall behind as far as the frames can.
  static std::uint32_t raw_batches(const DaemonConfig& c) { return c.arenas.count; }
  static std::size_t round_up(std::size_t n) {
    std::size_t p = 1;
    while (p < n)
      p <<= 1;
    return p;
  }

  PacketRing ring;
  std::vector<std::unique_ptr<FrameArena>> arenas;
  std::vector<std::unique_ptr<RawBatch>> raw;
  DecodeWorker::ArenaQueue free_arenas;
  DecodeWorker::RawQueue free_raw;
  DecodeWorker::WriterQueue to_writer;
  ringbuf::SpscQueue<StatusLine> status;
  ReceiveCounters receive;
  LiveClock live;
  Heartbeats heartbeats;
  std::atomic<bool> stop_source{false};
  std::atomic<bool> source_done{false};
  std::atomic<std::uint32_t> rotate_generation{0};
};

// From the writer's final health in memory, not from health.jsonl: when the disk is full the
// file's last line is an older one, and the summary must say how the run really ended.
void print_summary(const WriterOptions& wo, const HealthSnapshot& h) {
  const std::filesystem::path& dir = wo.output_dir;
  fmt::print("outputs in {}:\n  frames  {}\n  raw     {}\n  health  {} and {}\n", dir.string(),
             (dir / "frames").string(), (dir / "raw").string(), wo.prometheus_file.string(),
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
}

// The calibration the configuration names, or the nominal table. Throws on a bad file.
Calibration load_calibration(const DaemonConfig& config) {
  return config.sensor.calibration_file.empty() ? Calibration::nominal()
                                                : Calibration::load(config.sensor.calibration_file);
}

// The writer's options from the configuration. The decoder, the calibration and the recorded
// destination port are filled in at start, once known.
WriterOptions writer_options(const DaemonConfig& config) {
  const std::filesystem::path output_dir = config.output.directory;
  WriterOptions wo;
  wo.output_dir = output_dir;
  wo.health_dir = config.health.directory.empty() ? output_dir / "health"
                                                  : std::filesystem::path(config.health.directory);
  wo.prometheus_file = config.health.prometheus_file.empty()
                           ? wo.health_dir / "pandarcap.prom"
                           : std::filesystem::path(config.health.prometheus_file);
  if (const char* stall = std::getenv("PANDARCAP_TEST_STALL_WRITER_FILE")) {
    wo.test_stall_file = stall;
  }
  wo.frames = config.output.frames;
  wo.frames_max_files = config.output.frames_max_files;
  wo.frames_max_bytes = config.output.frames_max_bytes;
  wo.pcap = config.output.pcap;
  wo.pcap_rotate_bytes = config.output.pcap_rotate_bytes;
  wo.pcap_rotate_seconds = config.output.pcap_rotate_seconds;
  wo.pcap_max_files = config.output.pcap_max_files;
  wo.pcap_max_bytes = config.output.pcap_max_bytes;
  wo.prometheus = config.health.prometheus;
  wo.jsonl = config.health.jsonl;
  wo.jsonl_rotate_bytes = config.health.jsonl_rotate_bytes;
  wo.sensor_name = config.health.sensor_name;
  wo.version = std::string(kVersion);
  wo.no_data_timeout_seconds = config.health.no_data_timeout_seconds;
  wo.expected_return_mode = config.sensor.return_mode;
  wo.expected_rpm = config.sensor.rotation_speed;
  return wo;
}

// --check-config: what the start would refuse, short of opening the socket or the capture.
int check_config(const DaemonConfig& config, const std::string& source_name) {
  try {
    load_calibration(config);
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

int run(int argc, char** argv) {
  // A file-size limit (systemd's LimitFSIZE=, ulimit -f) must fail the one write with EFBIG,
  // counted like a full disk, not kill the daemon with SIGXFSZ.
  std::signal(SIGXFSZ, SIG_IGN);
  // 1. Options and configuration.
  Options options = parse_options(argc, argv);
  DaemonConfig config;
  const std::string source_name = options.config_path.value_or("command line");
  try {
    if (options.config_path) config = load_config_file(*options.config_path);
    for (const auto& apply : options.overrides)
      apply(config);
    validate_config(config, source_name);
  } catch (const ConfigError& error) {
    std::fprintf(stderr, "pandarcapd: %s\n", error.what());
    return kExitConfig;
  }
  if (options.check_config) return check_config(config, source_name);
  if (options.print_config) {
    fmt::print("{}", to_toml(config));
    return 0;
  }

  // 2. Logging and calibration.
  setup_logging(config.log_level);
  if (!options.print_calibration)
    spdlog::info("pandarcapd {} starting ({})", kVersion,
                 options.simulate ? "simulated sensor"
                 : options.replay ? "replay of " + *options.replay
                                  : "live capture");
  Calibration calibration;
  try {
    calibration = load_calibration(config);
  } catch (const std::exception& error) {
    spdlog::critical("{}", error.what());
    return kExitConfig;
  }
  if (options.print_calibration) {
    fmt::print("{}", calibration.to_csv());
    return 0;
  }
  // Checked before any socket or output file is opened. Reading the configuration and printing
  // tables above is harmless as root; parsing what arrives from the network is not.
  if (::geteuid() == 0 && !options.allow_root) {
    spdlog::critical(
        "refusing to run as root: pandarcapd needs no privilege (UDP on any port it is given, "
        "files it owns). Run it as an unprivileged user (the systemd unit uses 'pandarcap'), or "
        "pass --allow-root to accept the risk (containers, CI)");
    return kExitNoPermission;
  }
  if (::geteuid() == 0) spdlog::warn("running as root (--allow-root)");
  if (calibration.is_nominal()) {
    spdlog::warn(
        "calibration: nominal Pandar40P table in use (no calibration_file); per-unit "
        "elevations differ by up to ~0.45 degrees");
  } else {
    spdlog::info("calibration: {}", calibration.source);
  }

  // The decoder is chosen once, here; a named target this CPU cannot run is a configuration
  // error, not a reason to quietly run another.
  const DecoderChoice decoder_choice = choose_decoder_target(config.decoder);
  if (!decoder_choice.target) {
    spdlog::critical("{}", decoder_choice.error);
    return kExitConfig;
  }
  spdlog::info("decoder: {}{}", to_string(*decoder_choice.target),
               config.decoder == "auto" ? " (auto)" : "");

  // 3. Memory, all of it now.
  Pipeline pipe(config);
  spdlog::info(
      "memory: ring {} slots x {} B, {} frame arenas x {} points, {} raw batches x {} "
      "packets",
      config.ring.slots, sizeof(PacketSlot), config.arenas.count, config.arenas.points_per_frame,
      Pipeline::raw_batches(config), config.arenas.packets_per_frame);

  // 4. Source and outputs.
  std::unique_ptr<UdpReceiver> receiver;
  std::unique_ptr<ReplaySource> replay;
  std::unique_ptr<SimulatedSender> simulator;
  try {
    if (options.replay) {
      ReplayOptions ro;
      ro.path = *options.replay;
      ro.rate = options.rate;
      if (options.port_given) ro.destination_port = config.sensor.data_port;
      ro.sensor_ip = config.sensor.sensor_ip;
      replay = std::make_unique<ReplaySource>(ro);
    } else {
      UdpReceiverOptions ro;
      ro.host_ip = options.simulate ? "127.0.0.1" : config.sensor.host_ip;
      ro.port = options.simulate && !options.port_given ? 0 : config.sensor.data_port;
      ro.multicast_ip = options.simulate ? "" : config.sensor.multicast_ip;
      ro.multicast_interface_ip = config.sensor.multicast_interface_ip;
      ro.receive_buffer_bytes = config.sensor.udp_socket_receive_buffer_size_bytes;
      ro.sensor_ip = config.sensor.sensor_ip;
      ro.batch = config.ring.receive_batch;
      ro.latency_budget_ns = std::int64_t{config.latency.budget_ms} * 1'000'000;
      receiver = std::make_unique<UdpReceiver>(ro);
      if (options.simulate) {
        SyntheticSensorConfig sc;
        sc.rpm = options.simulated_rpm;
        sc.return_mode = options.simulated_mode;
        sc.udp_sequence = options.udp_sequence;
        sc.start_unix_ns = realtime_ns();
        simulator =
            std::make_unique<SimulatedSender>(sc, "127.0.0.1", "127.0.0.1", receiver->bound_port());
        spdlog::info("simulated sensor: {} RPM, {} return{}, sending to 127.0.0.1:{}", sc.rpm,
                     to_string(sc.return_mode), sc.udp_sequence ? ", UDP sequence" : "",
                     receiver->bound_port());
      }
    }
  } catch (const CaptureError& error) {
    spdlog::critical("{}", error.what());
    return kExitNoInput;
  } catch (const std::exception& error) {
    spdlog::critical("{}", error.what());
    return 1;
  }

  const std::filesystem::path output_dir = config.output.directory;
  WriterOptions wo = writer_options(config);
  wo.decoder = std::string(to_string(*decoder_choice.target));
  wo.calibration_csv = calibration.to_csv();
  wo.pcap_destination = Endpoint{0, receiver ? receiver->bound_port() : config.sensor.data_port};
  // One daemon per output directory, claimed before anything in it is touched (crash recovery,
  // numbering and retention all assume the files are this process's or a finished run's).
  std::optional<OutputDirectoryLock> lock;
  try {
    lock.emplace(output_dir);
  } catch (const OutputDirectoryBusy& error) {
    spdlog::critical("{}", error.what());
    return kExitCantCreate;
  } catch (const std::exception& error) {
    spdlog::critical("outputs: {}", error.what());
    return kExitCantCreate;
  }
  Writer writer(wo, pipe.to_writer, pipe.free_arenas, pipe.free_raw, pipe.receive, pipe.live);
  try {
    writer.prepare();
  } catch (const std::exception& error) {
    spdlog::critical("outputs: {}", error.what());
    return kExitCantCreate;
  }

  // 5. Threads. Signals are blocked first so every thread inherits the mask and only the main
  // thread takes them, synchronously, with sigtimedwait.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGHUP);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);

  DecodeWorkerOptions dopt;
  dopt.decoder.decoder.min_range_m = config.sensor.min_range;
  dopt.decoder.decoder.max_range_m = config.sensor.max_range;
  dopt.decoder.decoder.dual_return_distance_threshold_m =
      config.sensor.dual_return_distance_threshold;
  dopt.decoder.decoder.firing_time_correction = config.sensor.firing_time_correction;
  dopt.decoder.cut_angle_deg = config.sensor.cut_angle;
  dopt.decoder.decoder_target = *decoder_choice.target;
  dopt.frame_decimation = config.output.frame_decimation;
  dopt.write_frames = config.output.frames;
  dopt.min_frame_fraction = config.output.frames_min_fraction;
  dopt.expected_rpm = config.sensor.rotation_speed;
  dopt.record_raw = config.output.pcap;
  dopt.lossless = options.replay.has_value();
  dopt.measure_latency = !options.replay.has_value();
  DecodeWorker worker(calibration, dopt, pipe.ring, pipe.to_writer, pipe.free_arenas,
                      pipe.free_raw);

  ReplayResult replay_result;
  // Named threads (`top -H`, /proc/PID/task/*/comm) so each stage's CPU can be measured.
  const ThreadsSection& placement = config.threads;
  std::thread writer_thread([&] {
    name_this_thread("pc-writer");
    place_this_thread("writer", {placement.writer_cpu, placement.writer_priority});
    writer.run(pipe.heartbeats.writer, pipe.rotate_generation, pipe.status);
  });
  std::thread decode_thread([&] {
    name_this_thread("pc-decode");
    place_this_thread("decode", {placement.decode_cpu, placement.decode_priority});
    worker.run(pipe.source_done, pipe.heartbeats.decode, pipe.live);
  });
  std::thread source_thread([&] {
    name_this_thread(replay ? "pc-replay" : "pc-receive");
    place_this_thread("receive", {placement.receive_cpu, placement.receive_priority});
    if (replay) {
      replay_result =
          replay->run(pipe.ring, pipe.stop_source, pipe.receive, pipe.heartbeats.receive);
    } else {
      receiver->run(pipe.ring, pipe.stop_source, pipe.receive, pipe.heartbeats.receive);
    }
    // release: everything the source published happens before the decoder sees "done".
    pipe.source_done.store(true, std::memory_order_release);
  });
  std::atomic<bool> stop_simulator{false};
  std::thread simulator_thread;
  if (simulator) {
    simulator_thread = std::thread([&] {
      name_this_thread("pc-simsensor");
      simulator->run(stop_simulator);
    });
  }

  if (config.threads.lock_memory) lock_all_memory();
  systemd::ready();
  spdlog::info("ready: writing to {}", output_dir.string());

  // Supervision: signals, --duration, end of replay, STATUS and WATCHDOG.
  const auto start = std::chrono::steady_clock::now();
  const auto watchdog = systemd::watchdog_interval();
  const auto tick = std::chrono::milliseconds(100);
  auto next_watchdog = start;
  std::uint64_t seen[3] = {~0ull, ~0ull, ~0ull};
  for (;;) {
    const timespec timeout{0, std::chrono::nanoseconds(tick).count()};
    const int signal = sigtimedwait(&signals, nullptr, &timeout);
    if (signal == SIGTERM || signal == SIGINT) {
      spdlog::info("{}: stopping", signal == SIGTERM ? "SIGTERM" : "SIGINT");
      break;
    }
    if (signal == SIGHUP) pipe.rotate_generation.fetch_add(1, std::memory_order_relaxed);
    if (options.duration_s && std::chrono::steady_clock::now() - start >=
                                  std::chrono::duration<double>(*options.duration_s)) {
      spdlog::info("{} s elapsed: stopping", *options.duration_s);
      break;
    }
    if (pipe.source_done.load(std::memory_order_acquire)) break;  // replay finished
    StatusLine status;
    while (pipe.status.try_pop(status))
      systemd::status(status.text);
    const auto now = std::chrono::steady_clock::now();
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

  // Shutdown, in reverse: the simulator, the source, then the decoder drains the ring and the
  // writer finishes (partial frame renamed, pcap closed, final health).
  systemd::stopping();
  stop_simulator.store(true, std::memory_order_relaxed);
  if (simulator_thread.joinable()) simulator_thread.join();
  pipe.stop_source.store(true, std::memory_order_relaxed);
  source_thread.join();
  decode_thread.join();
  writer_thread.join();

  int status = 0;
  if (replay) {
    const auto& capture = replay_result.capture;
    spdlog::info(
        "replay: {} records, {} UDP datagrams ({} other ports, {} non-IPv4, {} non-UDP, "
        "{} fragments, {} malformed)",
        capture.records, capture.udp_datagrams, capture.port_filtered, capture.non_ipv4,
        capture.non_udp, capture.ip_fragments, capture.malformed);
    if (replay_result.status == CaptureStatus::kTruncated) {
      spdlog::warn("{}: the file ends in the middle of a record (cut off while recording)",
                   *options.replay);
    } else if (replay_result.status == CaptureStatus::kError) {
      spdlog::error("{}: {}", *options.replay, replay_result.error);
      status = 1;
    }
  }
  print_summary(wo, writer.final_health());
  return status;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return run(argc, argv);
  } catch (const std::exception& error) {
    std::fprintf(stderr, "pandarcapd: %s\n", error.what());
    return 1;
  }
}
