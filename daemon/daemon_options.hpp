// What the configuration means for each of the daemon's parts: pure functions from the checked
// DaemonConfig (and the few choices only the command line makes: the source, the replay's pace,
// the simulated sensor) to each thread's options. run() in pandarcapd_main.cpp calls them in its
// start-up order; the tests call them directly (tests/test_daemon_options.cpp).
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "config/daemon_config.hpp"
#include "core/decode/decoder_target.hpp"
#include "core/progress_line.hpp"
#include "core/sensors/packet.hpp"
#include "core/sim/synthetic_sensor.hpp"
#include "daemon/decode_worker.hpp"
#include "daemon/live/foxglove_server.hpp"
#include "daemon/output/writer.hpp"
#include "daemon/ptc/ptc_client.hpp"
#include "daemon/run_source.hpp"
#include "daemon/source/replay_source.hpp"
#include "daemon/source/udp_receiver.hpp"

namespace pandarcap {

// Whether anything consumes points: output.frames (PCD), output.mcap (its frames) or the live
// view (live.foxglove). Without any the decoder decodes only what the health needs, and the health
// leaves the point and frame counters out (StreamDecoderConfig::decode_points,
// HealthSnapshot::points_counted).
bool points_decoded(const DaemonConfig& config);

// The writer's options. The decoder's name, the calibration and the recorded destination port
// are known only at start (the caller fills them in); the test hook only in builds with
// PANDARCAP_TEST_HOOKS (the test builds; never the package).
// `model`: the sensor's as the start knows it (none: the configured one, else the Pandar40P),
// whose lower-case name is the `sensor` label when health.sensor_name is "".
WriterOptions writer_options(const DaemonConfig& config,
                             std::optional<SensorModelId> model = std::nullopt);
// Points an arena holds: arenas.points_per_frame, raised to what a revolution of the model can
// hold at sensor.rotation_speed in dual return, with 5 % to spare (the Pandar64's and the
// QT128's 230 400 at 600 RPM; the 40P's 151 200 stays under the default 180 000). A source whose
// packets choose the model (`model` none) is sized for the largest.
std::uint32_t arena_points(const DaemonConfig& config, std::optional<SensorModelId> model);
// health.sensor_name, or the model's lower-case name when it is "".
std::string sensor_label(const DaemonConfig& config, std::optional<SensorModelId> model);
// Where the health files go while their own directory cannot be written, in the order tried:
// health.fallback_directory when set, then the defaults (config/daemon_config.hpp), each once.
std::vector<std::filesystem::path> health_fallback_directories(const HealthSection& health,
                                                               std::string_view label);
// A replay shows its progress (core/progress_line.hpp) on stderr when that is a terminal and not
// systemd's journal (JOURNAL_STREAM): never in a pipe, a file or a service's log.
bool replay_progress_wanted();
ProgressLine replay_progress_line();
// output.device_name, or this host's name when it is "" ("unknown" if the host has none).
std::string device_name(const DaemonConfig& config);
// The effective configuration's hash: "xxh64:" and 16 hex digits of XXH64 (seed 0) of the text
// `pandarcapd --print-config` prints for it (to_toml), so `pandarcapd ... --print-config |
// xxhsum -H1` gives the same digits. Stable: the same configuration, the same hash, on any host
// (device_name is hashed as configured, "" when unset).
std::string config_hash(const DaemonConfig& config);

// The frames' layout and axes (output.pcd_fields, sensor.frame), which the arenas hold, the PCD
// files and MCAP write.
PcdFormat pcd_format(const DaemonConfig& config);

// The decode worker's options for the chosen decoder target and source.
DecodeWorkerOptions decode_worker_options(
    const DaemonConfig& config, DecoderTarget target, const RunSource& source,
    SensorModelId calibration_model = SensorModelId::kPandar40P);

// The live socket's options; the simulator's socket is on 127.0.0.1 (a free port unless
// --port), never a multicast group.
UdpReceiverOptions receiver_options(const DaemonConfig& config, const RunSource& source);

// The slots of the ring the decoder reads: ring.slots, except where the packet ring's receiver
// stages its blocks there (a live or simulated source with input.receiver = "packet_ring"): at most
// kPacketRingStagingSlots. There the ring only ever holds a part of one kernel block (the decoder
// empties it before it takes more), and 4096 slots (6 MiB) cycled every datagram through memory
// the cache had let go since the ring last came round.
inline constexpr std::uint32_t kPacketRingStagingSlots = 256;
std::uint32_t ring_slots(const DaemonConfig& config, const RunSource& source);

// The replay's options (source kReplay).
ReplayOptions replay_options(const DaemonConfig& config, const RunSource& source);

// Where the sensor's control port (PTC) is asked, if anywhere: live, sensor_ip:ptc_port
// (nothing without sensor_ip); simulated, 127.0.0.1 at the built-in server's port
// (`simulated_ptc_port`) or at --ptc-port; a replay asks only when calibration_source is
// "sensor" (and sensor_ip is set).
std::optional<PtcClientOptions> ptc_client_options(const DaemonConfig& config,
                                                   const RunSource& source,
                                                   std::uint16_t simulated_ptc_port);

// Whether the sensor's status is polled: a live or simulated source asked over PTC, with
// status_interval_seconds > 0.
bool status_polled(const DaemonConfig& config, const RunSource& source,
                   const std::optional<PtcClientOptions>& ptc);

// The live view's server ([live]; the points and health topics are the MCAP's), and the bytes of
// the largest frame's message, which the hand-over reserves: a frame of the arenas' points
// (arena_points, for `model`).
live::LiveOptions live_options(const DaemonConfig& config, std::string_view version,
                               std::optional<SensorModelId> model);
std::size_t live_points_capacity(const DaemonConfig& config, std::optional<SensorModelId> model);

// The simulated sensor's settings, starting now (`start_unix_ns`).
SyntheticSensorConfig simulated_sensor_config(const RunSource& source, std::int64_t start_unix_ns);

}  // namespace pandarcap
