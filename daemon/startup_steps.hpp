// pandarcapd's start-up steps, in the order run() takes them (pandarcapd_main.cpp): each does one
// thing, and a step that cannot go on throws StartupError with the exit status and the message,
// which run() reports once. Nothing here starts a pipeline thread; the simulated sensor's PTC
// server (learn_sensor) is the one thread a step may start, before the signals matter.
#pragma once

#include <signal.h>

#include <atomic>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "config/daemon_config.hpp"
#include "core/decode/decoder_target.hpp"
#include "daemon/output/output_directories.hpp"
#include "daemon/pandarcapd_command_line.hpp"
#include "daemon/ptc/ptc_client.hpp"
#include "daemon/ptc/sensor_at_start.hpp"
#include "daemon/ptc/simulated_ptc_server.hpp"
#include "daemon/run_source.hpp"
#include "daemon/source/packet_source.hpp"

namespace pandarcap {

// pandarcapd's exit statuses (sysexits.h's numbers; --help lists them).
inline constexpr int kExitUsage = 64;  // taken by CliArgs itself
// A replayed recording is not whole (damaged or cut short): sysexits' EX_DATAERR.
inline constexpr int kExitDataDamaged = 65;
inline constexpr int kExitNoInput = 66;
inline constexpr int kExitUnavailable = 69;
inline constexpr int kExitCantCreate = 73;
inline constexpr int kExitNoPermission = 77;
inline constexpr int kExitConfig = 78;

// A start-up step that cannot go on: the exit status and what to say. Thrown by the steps below,
// reported once by run().
struct StartupError {
  int exit_status;
  std::string message;
  // One problem a line, each escaped already (a configuration's, ConfigError); otherwise the
  // message is escaped whole when printed (core/log_text.hpp).
  bool lines = false;
};

// Signals while pandarcapd starts. Until the pipeline's threads start, SIGTERM and SIGINT go to
// a handler that only raises the stop flag and interrupts the main thread's wait (a sensor's
// answer over PTC): each step checks the flag, so a stop ends the start within a second, at any
// step. SIGHUP is taken and ignored until then (there is nothing to rotate). A thread started
// meanwhile (the simulated sensor's PTC server) starts inside a SignalsBlocked scope and never
// takes them. block_signals() then hands all three to supervise()'s sigtimedwait; one that came
// in between stays pending for it.
void take_signals_for_startup();
// Set by SIGTERM or SIGINT during the start; async-signal-safe to set (lock-free).
const std::atomic<bool>& stop_requested();
// Throws StartupError (exit 0: a stop asked for, not a failure) when the stop flag is up.
void stop_if_requested(std::string_view step);
// Blocks SIGTERM, SIGINT and SIGHUP in the calling thread, for good; the set, for sigtimedwait.
sigset_t block_signals();

// Blocks the three in the calling thread for its lifetime (threads started inside inherit it).
class SignalsBlocked {
 public:
  SignalsBlocked();
  ~SignalsBlocked();
  SignalsBlocked(const SignalsBlocked&) = delete;
  SignalsBlocked& operator=(const SignalsBlocked&) = delete;

 private:
  sigset_t previous_;
};

// The log: stderr, with the time unless journald adds its own (JOURNAL_STREAM).
void setup_logging(const std::string& level);

// 1. The configuration: the file, then the command line's keys, checked as a whole.
DaemonConfig load_configuration(const CommandLine& options, const std::string& source_name);

// What --check-config says about the live view's port: in use, not bindable, or held over IPv6
// by another program (warnings: the capture runs without the view). Empty when it is free.
std::vector<std::string> live_port_warnings(const LiveSection& live);
// --check-config: what the start would refuse, short of opening the socket or the capture (the
// live view's port is tried: a taken one is a warning). Returns the exit status, having printed
// the result.
int check_config(const DaemonConfig& config, const std::string& source_name);

// 1b. The sensor model (sensor.model): fixed, or for "auto" the one a replay's first packets name
// (an unsupported model's: a StartupError naming it), the simulated sensor's, or none yet for a
// live source (its packets choose it). Sets source.model and source.detect_model; logged.
void choose_sensor_model(const DaemonConfig& config, RunSource& source);

// 2. The sensor: its calibration (by calibration_source), identity and configuration. A
// simulated run first starts the simulated sensor's PTC server (`simulated_ptc`), to be asked as
// a real sensor is; `ptc` is where the sensor is asked, if anywhere.
SensorAtStart learn_sensor(const DaemonConfig& config, const RunSource& source,
                           std::unique_ptr<SimulatedPtcServer>& simulated_ptc,
                           std::optional<PtcClientOptions>& ptc);

// Checked before any socket or output file is opened. Reading the configuration and printing
// tables is harmless as root; parsing what arrives from the network is not.
void refuse_root_unless_allowed(const CommandLine& options, const DaemonConfig& config);

// What the sensor said at start, and where it disagrees with what this daemon expects.
void log_sensor(const SensorAtStart& sensor, const DaemonConfig& config, const RunSource& source);

// The decoder is chosen once, here; a named target this CPU cannot run is a configuration
// error, not a reason to quietly run another.
DecoderTarget choose_decoder(const DaemonConfig& config);

// The source the command line names, opened (socket bound, file open): 66 for a capture that
// cannot be read.
std::unique_ptr<PacketSource> open_source(const DaemonConfig& config, const RunSource& source);

// One daemon per output directory, claimed before anything in it is touched (crash recovery,
// numbering and retention all assume the files are this process's or a finished run's).
std::unique_ptr<OutputDirectoryLock> claim_outputs(const std::filesystem::path& directory);

// "live capture", "simulated sensor", "replay of FILE": for the log.
std::string describe(const RunSource& source);

}  // namespace pandarcap
