#include "daemon/startup_steps.hpp"

#include <fmt/format.h>
#include <pthread.h>
#include <signal.h>
#include <spdlog/pattern_formatter.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <vector>

#include "config/config_loader.hpp"
#include "core/decode/calibration.hpp"
#include "core/log_text.hpp"
#include "core/sensors/sensor_models.hpp"
#include "core/sim/simulated_unit.hpp"
#include "daemon/clocks.hpp"
#include "daemon/daemon_options.hpp"
#include "daemon/io/calibration_file.hpp"
#include "daemon/live/live_handover.hpp"
#include "daemon/live/live_port_probe.hpp"
#include "daemon/pcap/capture_reader.hpp"
#include "daemon/pcap/recording_calibration.hpp"
#include "daemon/pcap/recording_model.hpp"

namespace pandarcap {

namespace {

std::atomic<bool> stop_flag{false};
static_assert(std::atomic<bool>::is_always_lock_free, "set from a signal handler");

extern "C" void on_stop_signal(int) {
  stop_flag.store(true, std::memory_order_relaxed);
}
extern "C" void on_hangup_during_startup(int) {}

sigset_t the_three() {
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGHUP);
  return signals;
}

}  // namespace

void take_signals_for_startup() {
  struct sigaction action {};
  sigemptyset(&action.sa_mask);
  action.sa_flags = 0;  // no SA_RESTART: a wait in progress returns EINTR and checks the flag
  action.sa_handler = on_stop_signal;
  sigaction(SIGTERM, &action, nullptr);
  sigaction(SIGINT, &action, nullptr);
  // A handler, not SIG_IGN: an ignored signal is discarded even while blocked, and supervise()
  // waits for SIGHUP later.
  action.sa_handler = on_hangup_during_startup;
  sigaction(SIGHUP, &action, nullptr);
  const sigset_t signals = the_three();
  pthread_sigmask(SIG_UNBLOCK, &signals, nullptr);
}

const std::atomic<bool>& stop_requested() {
  return stop_flag;
}

void stop_if_requested(std::string_view step) {
  if (stop_flag.load(std::memory_order_relaxed)) {
    throw StartupError{0,
                       fmt::format("stop requested while starting ({}): nothing to finish", step)};
  }
}

sigset_t block_signals() {
  const sigset_t signals = the_three();
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);
  return signals;
}

SignalsBlocked::SignalsBlocked() {
  const sigset_t signals = the_three();
  pthread_sigmask(SIG_BLOCK, &signals, &previous_);
}

SignalsBlocked::~SignalsBlocked() {
  pthread_sigmask(SIG_SETMASK, &previous_, nullptr);
}

namespace {

// A log line's message with its control characters escaped (core/log_text.hpp): any line may
// carry a configured path, a file name or what the network sent, and none may forge a line.
class EscapedMessage final : public spdlog::custom_flag_formatter {
 public:
  void format(const spdlog::details::log_msg& message, const std::tm&,
              spdlog::memory_buf_t& out) override {
    append_escaped_control(std::string_view(message.payload.data(), message.payload.size()), out);
  }
  std::unique_ptr<custom_flag_formatter> clone() const override {
    return std::make_unique<EscapedMessage>();
  }
};

}  // namespace

void setup_logging(const std::string& level) {
  auto logger = spdlog::stderr_color_mt("pandarcapd");
  auto formatter = std::make_unique<spdlog::pattern_formatter>();
  // Under systemd, journald timestamps every line itself.
  formatter->add_flag<EscapedMessage>('*').set_pattern(
      std::getenv("JOURNAL_STREAM") != nullptr ? "[%l] %*" : "%Y-%m-%dT%H:%M:%S.%e [%l] %*");
  logger->set_formatter(std::move(formatter));
  logger->set_level(spdlog::level::from_str(level));
  spdlog::set_default_logger(logger);
}

std::vector<std::string> live_port_warnings(const LiveSection& live) {
  std::vector<std::string> warnings;
  const int error = live::probe_ipv4_port(live.address, live.port);
  if (error == EADDRINUSE) {
    warnings.push_back(fmt::format(
        "live view: port {} in use on {} (by another program: foxglove_bridge listens on 8765 "
        "too); the capture runs without the view, which tries again every {} s",
        live.port, live.address, live::kListenRetrySeconds));
  } else if (error != 0) {
    warnings.push_back(
        fmt::format("live view: cannot listen on {}:{}: {}; the capture runs "
                    "without the view, which tries again every {} s",
                    live.address, live.port, std::strerror(error), live::kListenRetrySeconds));
  }
  if (live::ipv6_loopback_port_taken(live.port)) {
    warnings.push_back(fmt::format(
        "live view: port {} is held on IPv6 (::1) by another program: a viewer that opens "
        "ws://localhost:{} may reach that one; open ws://{}:{}",
        live.port, live.port, live.address, live.port));
  }
  return warnings;
}

int check_config(const DaemonConfig& config, const std::string& source_name) {
  try {
    // The file the start would read; the sensor is not asked (no network here).
    const SensorSection& s = config.sensor;
    if (s.calibration_source != "nominal" && !s.calibration_file.empty()) {
      std::optional<SensorModelId> model;  // "auto": any supported model's table
      if (s.model != "auto") model = parse_sensor_model(s.model);
      load_calibration(s.calibration_file, model);
    }
  } catch (const std::exception& error) {
    std::fprintf(stderr, "pandarcapd: %s\n", escaped_control(error.what()).c_str());
    return kExitConfig;
  }
  const DecoderChoice decoder = choose_decoder_target(config.decoder);
  if (!decoder.target) {
    std::fprintf(stderr, "pandarcapd: %s: decoder: %s\n", escaped_control(source_name).c_str(),
                 escaped_control(decoder.error).c_str());
    return kExitConfig;
  }
  const WriterOptions outputs = writer_options(config);
  std::vector<std::string> problems = output_problems(outputs);
  std::vector<std::string> space;
  for (std::string& problem : space_problems(outputs, space))
    problems.push_back(std::move(problem));
  for (const std::string& line : space)
    fmt::print("free space: {}\n", escaped_control(line));
  for (const std::string& line : floor_report(outputs))
    fmt::print("free-space floor: {}\n", escaped_control(line));
  for (const std::string& line : health_fallback_report(outputs))
    fmt::print("health fallback: {}\n", escaped_control(line));
  if (outputs.upload) {
    fmt::print(
        "upload: raw/ and mcap/{} leave by upload (output.upload): the health says how far it is "
        "behind, and counts files removed before they were uploaded\n",
        outputs.upload_frames ? " and frames/" : "");
  }
  for (const std::string& problem : problems)
    std::fprintf(stderr, "pandarcapd: %s: outputs: %s\n", escaped_control(source_name).c_str(),
                 escaped_control(problem).c_str());
  if (!problems.empty()) return kExitCantCreate;
  // The live view's port, tried: one another program holds is a warning, not a failure (the
  // capture runs without the view, which binds once the port is free; docs/live.md).
  if (config.live.foxglove) {
    for (const std::string& warning : live_port_warnings(config.live))
      std::fprintf(stderr, "pandarcapd: %s: warning: %s\n", escaped_control(source_name).c_str(),
                   escaped_control(warning).c_str());
  }
  fmt::print("{}: configuration OK\n", escaped_control(source_name));
  return 0;
}

DaemonConfig load_configuration(const CommandLine& options, const std::string& source_name) {
  try {
    DaemonConfig config;
    if (options.config_path) config = load_config_file(*options.config_path);
    for (const auto& [key, text] : options.overrides)
      set_config_value(config, key, text, source_name);
    validate_config(config, source_name);
    return config;
  } catch (const ConfigError& error) {
    throw StartupError{kExitConfig, error.what(), true};
  }
}

void refuse_root_unless_allowed(const CommandLine& options, const DaemonConfig& config) {
  if (::geteuid() != 0) return;
  // The packet ring needs CAP_NET_RAW: root is one way to have it (the drop-in, for an
  // unprivileged user, the better one). A replay never opens it; a simulated run opens it on lo.
  if (config.input.receiver == "packet_ring" && options.source.kind != RunSource::Kind::kReplay) {
    spdlog::warn(
        "running as root for input.receiver = \"packet_ring\" (CAP_NET_RAW); an unprivileged "
        "user with the capability alone is safer (the systemd drop-in "
        "pandarcapd-packet-ring.conf; docs/deploy.md)");
    return;
  }
  if (!options.allow_root) {
    throw StartupError{
        kExitNoPermission,
        "refusing to run as root: pandarcapd needs no privilege (UDP on any port it is given, "
        "files it owns). Run it as an unprivileged user (the systemd unit uses 'pandarcap'), or "
        "pass --allow-root to accept the risk (containers, CI); input.receiver = \"packet_ring\" "
        "is the one setting that needs a privilege (CAP_NET_RAW), and runs as root without it"};
  }
  spdlog::warn("running as root (--allow-root)");
}

void log_sensor(const SensorAtStart& sensor, const DaemonConfig& config, const RunSource& source) {
  if (sensor.calibration_source == "nominal") {
    spdlog::warn(
        "calibration: nominal {} table in use (no sensor answer, no calibration_file); "
        "per-unit angles differ from it by up to ~0.5 degrees",
        display_name(sensor.calibration.model()));
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

namespace {

// The calibration a replayed recording carries (daemon/pcap/recording_calibration.hpp), as the
// sensor's facts at start: calibration_source "recording". None: nothing, said in the log (the
// nominal table follows). One there but unusable: a CalibrationError (exit 78).
std::optional<SensorAtStart> recording_sensor(const std::string& path,
                                              std::optional<SensorModelId> model) {
  std::string looked_for;
  std::optional<Calibration> table = recording_calibration(path, looked_for, model);
  if (!table) {
    spdlog::warn(
        "calibration: the recording carries none (looked for {}): the nominal table is used; give "
        "the sensor's with --calibration FILE",
        looked_for);
    return std::nullopt;
  }
  SensorAtStart sensor;
  sensor.calibration = std::move(*table);
  sensor.calibration_source = "recording";
  return sensor;
}

}  // namespace

namespace {

// The simulated sensor spins and returns as its model can (a QT128 at 600 RPM only).
void check_simulated(const RunSource& source) {
  with_model(source.simulated_model, [&]<class M>(std::type_identity<M>) {
    if (std::find(M::kSupportedRpms.begin(), M::kSupportedRpms.end(), source.simulated_rpm) ==
        M::kSupportedRpms.end()) {
      throw StartupError{kExitConfig, fmt::format("a simulated {} does not spin at {} RPM",
                                                  display_name(M::kId), source.simulated_rpm)};
    }
    if (!mode_listed(M::kReturnModes, source.simulated_mode)) {
      throw StartupError{kExitConfig,
                         fmt::format("a simulated {} does not send {} return", display_name(M::kId),
                                     to_string(source.simulated_mode))};
    }
  });
}

}  // namespace

namespace {

void choose_model(const DaemonConfig& config, RunSource& source);

}  // namespace

void choose_sensor_model(const DaemonConfig& config, RunSource& source) {
  choose_model(config, source);
  // The firing-time correction is the 40P's alone (its tuned decoders apply it).
  if (!config.sensor.firing_time_correction) return;
  if (source.model && *source.model != SensorModelId::kPandar40P) {
    throw StartupError{kExitConfig,
                       fmt::format("sensor.firing_time_correction applies to the Pandar40P only, "
                                   "not to a {}: turn it off",
                                   display_name(*source.model))};
  }
  if (!source.model) {
    spdlog::warn(
        "sensor.firing_time_correction: applied only if the packets are a Pandar40P's (the "
        "other models' points are placed without it)");
  }
}

namespace {

void choose_model(const DaemonConfig& config, RunSource& source) {
  if (config.sensor.model != "auto") {
    source.model = parse_sensor_model(config.sensor.model);  // checked with the configuration
    spdlog::info("sensor model: {} (sensor.model)", display_name(*source.model));
    if (source.kind == RunSource::Kind::kSimulated) {
      source.simulated_model = *source.model;
      check_simulated(source);
    }
    return;
  }
  switch (source.kind) {
    case RunSource::Kind::kSimulated:
      source.model = source.simulated_model;
      spdlog::info("sensor model: {} (the simulated sensor)", display_name(*source.model));
      check_simulated(source);
      return;
    case RunSource::Kind::kLive:
      source.detect_model = true;
      spdlog::info("sensor model: auto (the first packets name it)");
      return;
    case RunSource::Kind::kReplay:
      break;
  }
  std::optional<RecordingModel> found;
  try {
    std::optional<std::uint16_t> port;
    if (source.port_given) port = config.sensor.data_port;
    found = recording_model(source.replay_path, port);
  } catch (const CaptureError&) {
    return;  // the replay's own open says what is wrong with the file
  }
  if (!found) {
    // The packets choose, as live: the first of a known model, wherever it is in the file.
    spdlog::warn(
        "sensor model: none of the first packets of {} names a model pandarcap knows: "
        "the first that does will",
        source.replay_path);
    source.detect_model = true;
    return;
  }
  if (found->detected.kind == DetectionKind::kUnsupported) {
    throw StartupError{
        kExitNoInput,
        fmt::format("{}: its packets are a Hesai {}, which pandarcap does not decode (it decodes "
                    "the Pandar40P, Pandar64, PandarXT32, PandarXT16 and PandarQT128)",
                    source.replay_path, found->detected.unsupported_name)};
  }
  source.model = found->detected.model;
  if (found->from_file) {
    spdlog::info("sensor model: {} (no packet of the first names one: the file's sensor_model)",
                 display_name(*source.model));
    return;
  }
  spdlog::info("sensor model: {} (from the recording's packets)", display_name(*source.model));
  if (found->named && *found->named != *source.model) {
    spdlog::warn("sensor model: {} names {}, its packets are a {}: the packets are decoded as a {}",
                 source.replay_path, display_name(*found->named), display_name(*source.model),
                 display_name(*source.model));
  }
}

}  // namespace

SensorAtStart learn_sensor(const DaemonConfig& config, const RunSource& source,
                           std::unique_ptr<SimulatedPtcServer>& simulated_ptc,
                           std::optional<PtcClientOptions>& ptc) {
  try {
    if (source.kind == RunSource::Kind::kSimulated && !source.ptc_port_given) {
      const SignalsBlocked blocked;  // its thread must never take the daemon's signals
      simulated_ptc = std::make_unique<SimulatedPtcServer>(simulated_unit(
          source.simulated_rpm, static_cast<std::uint8_t>(source.simulated_mode),
          source.simulated_udp_sequence, config.sensor.data_port, source.simulated_model));
    }
    ptc = ptc_client_options(config, source, simulated_ptc ? simulated_ptc->port() : 0);
    if (ptc) ptc->cancel = &stop_requested();
    // A replay given no calibration takes the recording's own, before the nominal table.
    if (source.kind == RunSource::Kind::kReplay && config.sensor.calibration_source == "auto" &&
        config.sensor.calibration_file.empty()) {
      if (std::optional<SensorAtStart> own = recording_sensor(source.replay_path, source.model)) {
        return *own;
      }
    }
    return resolve_sensor_at_start(config.sensor.calibration_source, config.sensor.calibration_file,
                                   ptc, source.model);
  } catch (const SensorUnavailable& error) {
    stop_if_requested("asking the sensor");  // it did not answer because the wait was cut short
    throw StartupError{kExitUnavailable, error.what()};
  } catch (const CalibrationError& error) {
    throw StartupError{kExitConfig, error.what()};
  } catch (const std::exception& error) {
    throw StartupError{1, error.what()};
  }
}

DecoderTarget choose_decoder(const DaemonConfig& config) {
  const DecoderChoice choice = choose_decoder_target(config.decoder);
  if (!choice.target) throw StartupError{kExitConfig, choice.error};
  spdlog::info("decoder: {}{}", to_string(*choice.target),
               config.decoder == "auto" ? " (auto)" : "");
  return *choice.target;
}

std::unique_ptr<PacketSource> open_source(const DaemonConfig& config, const RunSource& source) {
  try {
    if (source.kind == RunSource::Kind::kReplay) {
      return PacketSource::replay(replay_options(config, source));
    }
    const UdpReceiverOptions options = receiver_options(config, source);
    const std::int64_t asked_ns = std::int64_t{config.latency.budget_ms} * 1'000'000;
    if (options.latency_budget_ns < asked_ns) {
      spdlog::info(
          "latency.budget_ms {} shortened to {:.1f} ms: no wake may take more than a quarter of "
          "what the ring, the raw batches and the arenas hold at the sensor's rate, nor wait "
          "more than a quarter of health.no_data_timeout_seconds",
          config.latency.budget_ms, static_cast<double>(options.latency_budget_ns) / 1e6);
    }
    if (source.kind == RunSource::Kind::kSimulated) {
      return PacketSource::simulated(options, source.simulated_model,
                                     simulated_sensor_config(source, realtime_ns()));
    }
    return PacketSource::live(options);
  } catch (const CaptureError& error) {
    throw StartupError{kExitNoInput, error.what()};
  } catch (const MissingCapability& error) {
    throw StartupError{kExitNoPermission, error.what()};
  } catch (const NoSuchInterface& error) {
    throw StartupError{kExitConfig, error.what()};
  } catch (const std::exception& error) {
    throw StartupError{1, error.what()};
  }
}

std::unique_ptr<OutputDirectoryLock> claim_outputs(const std::filesystem::path& directory) {
  try {
    return std::make_unique<OutputDirectoryLock>(directory);
  } catch (const OutputDirectoryBusy& error) {
    throw StartupError{kExitCantCreate, error.what()};
  } catch (const std::exception& error) {
    throw StartupError{kExitCantCreate, fmt::format("outputs: {}", error.what())};
  }
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

}  // namespace pandarcap
