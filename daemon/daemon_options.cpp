#include "daemon/daemon_options.hpp"

#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <string_view>
#include <type_traits>

#include "config/command_line.hpp"
#include "config/config_loader.hpp"
#include "core/mcap/ros2_messages.hpp"
#include "core/sensors/sensor_models.hpp"
#include "core/units.hpp"
#include "daemon/live/live_publish.hpp"
#include "daemon/mcap/mcap_file.hpp"
#include "daemon/pcap/xxh64.hpp"
#include "daemon/pipeline.hpp"
#include "daemon/pipeline_types.hpp"
#include "daemon/source/packet_ring_receiver.hpp"

namespace pandarcap {

PcdFormat pcd_format(const DaemonConfig& config) {
  // Both were checked when the configuration was read.
  return PcdFormat{parse_pcd_layout(config.output.pcd_fields).value_or(PcdLayout::kPcl),
                   parse_axes(config.sensor.frame).value_or(Axes::kHesai)};
}

bool points_decoded(const DaemonConfig& config) {
  // MCAP and the live view take the same frames (and packets) as the PCD files (and the pcap).
  return config.output.frames || config.output.mcap || config.live.foxglove;
}

// A quarter of what the pipeline holds: the ring's slots; when the pcap or MCAP records
// packets, the raw batches between decoder and writer; and when points are decoded, the frames
// the arenas hold (each a revolution of `model` in dual return at sensor.rotation_speed: a wake
// of more frames than the writer has arenas for drops frames). Everything a wake takes arrives at
// once.
std::size_t max_wake_datagrams(const DaemonConfig& config, SensorModelId model) {
  std::size_t held = config.ring.slots;
  if (config.output.pcap || (config.output.mcap && config.output.mcap_packets)) {
    held = std::min<std::size_t>(
        held, std::size_t{Pipeline::raw_batches(config)} * config.arenas.packets_per_frame);
  }
  if (points_decoded(config)) {
    const double per_frame = with_model(model, [&]<class M>(std::type_identity<M>) {
      return std::ceil(M::packets_per_revolution(2, config.sensor.rotation_speed));
    });
    held = std::min<std::size_t>(
        held, static_cast<std::size_t>(per_frame) * std::size_t{config.arenas.count});
  }
  return std::max<std::size_t>(held / 4, 1);
}

// The longest any wake lets packets wait, whatever latency.budget_ms asks: no longer than
// max_wake_datagrams take to arrive at the sensor's rate, nor than a quarter of the silence that
// health calls no_data (a longer wait fakes one: budget_ms = 1000 with no_data_timeout_seconds =
// 0.3 said no_data twice a second while the sensor sent). 1 ms at least.
std::int64_t longest_wait_ns(const DaemonConfig& config, SensorModelId model,
                             double packets_per_second) {
  double seconds = static_cast<double>(max_wake_datagrams(config, model)) / packets_per_second;
  seconds = std::min(seconds, config.health.no_data_timeout_seconds / 4);
  return std::max<std::int64_t>(static_cast<std::int64_t>(seconds * 1e9), 1'000'000);
}

// How long a recording alone lets packets wait before the receive thread hands them on: the
// decoder's flush period, or less (longest_wait_ns).
std::int64_t recording_wait_ns(const DaemonConfig& config, SensorModelId model,
                               double packets_per_second) {
  return std::min(kRecordingFlushNs, longest_wait_ns(config, model, packets_per_second));
}

std::string device_name(const DaemonConfig& config) {
  if (!config.output.device_name.empty()) return config.output.device_name;
  char host[256] = {};
  if (::gethostname(host, sizeof host - 1) != 0 || host[0] == '\0') return "unknown";
  return host;
}

std::string config_hash(const DaemonConfig& config) {
  const std::string text = to_toml(config);
  Xxh64 hash;
  hash.update({reinterpret_cast<const std::uint8_t*>(text.data()), text.size()});
  return fmt::format("xxh64:{:016x}", hash.digest());
}

bool replay_progress_wanted() {
  return ::isatty(STDERR_FILENO) == 1 && std::getenv("JOURNAL_STREAM") == nullptr;
}

ProgressLine replay_progress_line() {
#ifdef PANDARCAP_TEST_HOOKS
  // Test hook: a quiet start this short (seconds), a line every tick, so that a replay of a
  // second shows its progress.
  if (const char* quiet = std::getenv("PANDARCAP_TEST_PROGRESS_QUIET_S"))
    return ProgressLine(std::atof(quiet), 0.05);
#endif
  return ProgressLine();
}

std::uint32_t arena_points(const DaemonConfig& config, std::optional<SensorModelId> model) {
  std::uint32_t points = config.arenas.points_per_frame;
  for (SensorModelId id : kSensorModelIds) {
    if (model && *model != id) continue;
    const double need = with_model(id, [&]<class M>(std::type_identity<M>) {
      return std::ceil(M::packets_per_revolution(2, config.sensor.rotation_speed) *
                       M::kMaxPointsPerPacket * 1.05);
    });
    points = std::max(points, static_cast<std::uint32_t>(need));
  }
  return points;
}

std::string sensor_label(const DaemonConfig& config, std::optional<SensorModelId> model) {
  if (!config.health.sensor_name.empty()) return config.health.sensor_name;
  if (!model && config.sensor.model != "auto") model = parse_sensor_model(config.sensor.model);
  return std::string(lower_case_name(model.value_or(SensorModelId::kPandar40P)));
}

WriterOptions writer_options(const DaemonConfig& config, std::optional<SensorModelId> model) {
  const std::filesystem::path output_dir = config.output.directory;
  WriterOptions wo;
  wo.output_dir = output_dir;
  wo.device_name = device_name(config);
  wo.config_hash = config_hash(config);
  wo.health_dir = config.health.directory.empty() ? output_dir / "health"
                                                  : std::filesystem::path(config.health.directory);
  wo.prometheus_file = config.health.prometheus_file.empty()
                           ? wo.health_dir / "pandarcap.prom"
                           : std::filesystem::path(config.health.prometheus_file);
#ifdef PANDARCAP_TEST_HOOKS
  if (const char* stall = std::getenv("PANDARCAP_TEST_STALL_WRITER_FILE")) {
    wo.test_stall_file = stall;
  }
#endif
  wo.frames = config.output.frames;
  wo.points_counted = points_decoded(config);
  wo.frames_max_files = config.output.frames_max_files;
  wo.frames_max_bytes = config.output.frames_max_bytes;
  wo.pcap = config.output.pcap;
  wo.pcap_rotate_bytes = config.output.pcap_rotate_bytes;
  wo.pcap_rotate_seconds = config.output.pcap_rotate_seconds;
  wo.pcap_max_files = config.output.pcap_max_files;
  wo.pcap_max_bytes = config.output.pcap_max_bytes;
  wo.pcap_zstd = config.output.pcap_compression == "zstd";
  wo.pcap_zstd_level = config.output.pcap_compression_level;
  wo.pcd_lzf = config.output.pcd_compression == "lzf";
  // As many as the arenas hold (arena_points: at least what the model's revolution needs), or a
  // frame that fills its arena would not fit the lzf compressor or an MCAP message.
  wo.max_frame_points = arena_points(config, model);
  wo.min_free_bytes = config.output.min_free_bytes;
  wo.min_free_percent = config.output.min_free_percent;
  wo.upload = config.output.upload;
  wo.upload_frames = config.output.upload_frames;
  wo.min_hours_left = config.health.min_hours_left;
  wo.sync_interval_seconds = config.output.sync_interval_seconds;
  wo.health_fallback_dirs = health_fallback_directories(config.health, sensor_label(config, model));
  const OutputSection& o = config.output;
  wo.mcap = o.mcap;
  wo.pcd_format = pcd_format(config);
  wo.mcap_file.format = wo.pcd_format;
  wo.mcap_rotate_bytes = o.mcap_rotate_bytes;
  wo.mcap_rotate_seconds = o.mcap_rotate_seconds;
  wo.mcap_max_files = o.mcap_max_files;
  wo.mcap_max_bytes = o.mcap_max_bytes;
  wo.mcap_file.compression = o.mcap_compression == "none"
                                 ? mcap::ChunkCompression::kNone
                                 : mcap::parse_compression_name(o.mcap_compression)
                                       .value_or(mcap::ChunkCompression::kZstd);
  wo.mcap_file.compression_level = o.mcap_compression_level;
  wo.mcap_file.chunk_bytes = o.mcap_chunk_bytes;
  wo.mcap_file.chunk_crc = o.mcap_chunk_crc;
  wo.mcap_file.max_frame_points = wo.max_frame_points;
  wo.mcap_file.packets = o.mcap_packets;
  wo.mcap_file.points_topic = o.mcap_points_topic;
  wo.mcap_file.health_topic = o.mcap_health_topic;
  wo.mcap_file.packets_topic = o.mcap_packets_topic;
  wo.mcap_file.frame_id = o.mcap_frame_id;
  if (model) wo.mcap_file.sensor_model = display_name(*model);
  wo.prometheus = config.health.prometheus;
  wo.jsonl = config.health.jsonl;
  wo.jsonl_rotate_bytes = config.health.jsonl_rotate_bytes;
  wo.sensor_name = sensor_label(config, model);
  // A live "auto" learns its model from the packets: the label follows it.
  wo.sensor_name_from_model = config.health.sensor_name.empty() && config.sensor.model == "auto";
  wo.version = PANDARCAP_VERSION;
  wo.no_data_timeout_seconds = config.health.no_data_timeout_seconds;
  wo.max_sensor_clock_offset_seconds = config.health.max_sensor_clock_offset_seconds;
  wo.expected_return_mode = config.sensor.return_mode;
  wo.expected_rpm = config.sensor.rotation_speed;
  return wo;
}

std::vector<std::filesystem::path> health_fallback_directories(const HealthSection& health,
                                                               std::string_view label) {
  std::vector<std::filesystem::path> dirs;
  const auto add = [&](std::filesystem::path dir) {
    if (std::find(dirs.begin(), dirs.end(), dir) == dirs.end()) dirs.push_back(std::move(dir));
  };
  if (!health.fallback_directory.empty()) add(health.fallback_directory);
  // systemd's RuntimeDirectory= (the packaged unit: /run/pandarcap/NAME): a tmpfs of the
  // instance's own, which a failing disk cannot take with it.
  if (const char* runtime = std::getenv("RUNTIME_DIRECTORY"); runtime != nullptr && *runtime) {
    // Several directories are separated by ':'; the first is the instance's.
    const std::string_view all(runtime);
    add(std::filesystem::path(all.substr(0, all.find(':'))));
  }
  // Outside systemd, one directory per sensor label (unique per sensor, as its metrics are).
  if (const char* user = std::getenv("XDG_RUNTIME_DIR"); user != nullptr && *user) {
    add(std::filesystem::path(user) / "pandarcap" / label);
  }
  add(std::filesystem::path(fmt::format("/tmp/pandarcap-{}", ::getuid())) / label);
  return dirs;
}

DecodeWorkerOptions decode_worker_options(const DaemonConfig& config, DecoderTarget target,
                                          const RunSource& source,
                                          SensorModelId calibration_model) {
  const bool replay = source.kind == RunSource::Kind::kReplay;
  DecodeWorkerOptions dopt;
  dopt.decoder = stream_decoder_config(config);
  dopt.decoder.decoder_target = target;
  dopt.detect_model = source.detect_model;
  // A live "auto" starts as the table's model (a Pandar40P's nominal one, or a file's), until
  // the first packet names it.
  dopt.model = source.model.value_or(calibration_model);
  dopt.frame_decimation = config.output.frame_decimation;
  dopt.write_frames = points_decoded(config);
  dopt.decoder.decode_points = dopt.write_frames;
  dopt.min_frame_fraction = config.output.frames_min_fraction;
  dopt.expected_rpm = config.sensor.rotation_speed;
  dopt.record_raw = config.output.pcap || (config.output.mcap && config.output.mcap_packets);
  dopt.lossless = replay;
  dopt.measure_latency = !replay;
  return dopt;
}

std::uint32_t ring_slots(const DaemonConfig& config, const RunSource& source) {
  const bool staging =
      source.kind != RunSource::Kind::kReplay && config.input.receiver == "packet_ring";
  return staging ? std::min(config.ring.slots, kPacketRingStagingSlots) : config.ring.slots;
}

UdpReceiverOptions receiver_options(const DaemonConfig& config, const RunSource& source) {
  const bool simulate = source.kind == RunSource::Kind::kSimulated;
  UdpReceiverOptions ro;
  ro.host_ip = simulate ? "127.0.0.1" : config.sensor.host_ip;
  ro.port = simulate && !source.port_given ? 0 : config.sensor.data_port;
  ro.multicast_ip = simulate ? "" : config.sensor.multicast_ip;
  ro.multicast_interface_ip = config.sensor.multicast_interface_ip;
  ro.receive_buffer_bytes = config.sensor.udp_socket_receive_buffer_size_bytes;
  ro.sensor_ip = config.sensor.sensor_ip;
  ro.batch = config.ring.receive_batch;
  ro.packet_ring = config.input.receiver == "packet_ring";
  // The simulated sensor sends over loopback, whatever interface the configuration names.
  ro.interface = simulate ? "lo" : config.sensor.interface;
  // The configured model's dual-return rate, with its frames' headers; a 40P's while "auto".
  const SensorModelId model = source.model.value_or(SensorModelId::kPandar40P);
  const double packets_per_second =
      with_model(model, []<class M>(std::type_identity<M>) { return M::packets_per_second(2); });
  ro.expected_datagram_bytes = with_model(model, []<class M>(std::type_identity<M>) {
    return std::uint64_t{M::kMaxDatagramBytes + 42};
  });
  ro.expected_bytes_per_second = static_cast<std::uint64_t>(
      packets_per_second * static_cast<double>(ro.expected_datagram_bytes));
  ro.max_wake_datagrams = max_wake_datagrams(config, model);
  ro.latency_budget_ns = std::int64_t{config.latency.budget_ms} * 1'000'000;
  // The budget is the frames' (users wait for frames). A recording alone waits for nothing
  // sooner than the decoder's flush of its packets to the writer: waking more often than that
  // would cost wake-ups and buy nothing. A budget of 0 (a wake per datagram) is asked for as such.
  // The packet ring only: its blocks are handed over when full, so a burst wakes it; a socket
  // cannot wake on a fill level (SO_RCVLOWAT does not apply to UDP), and a long sleep would meet
  // a burst (ten times the rate for 100 ms) with all of it at once.
  if (ro.packet_ring && !points_decoded(config) && ro.latency_budget_ns > 0) {
    ro.latency_budget_ns =
        std::max(ro.latency_budget_ns, recording_wait_ns(config, model, packets_per_second));
  }
  // A budget is an upper bound, not a promise to wait: none may wait longer than the pipeline
  // and the health allow.
  if (ro.latency_budget_ns > 0) {
    ro.latency_budget_ns =
        std::min(ro.latency_budget_ns, longest_wait_ns(config, model, packets_per_second));
    // The packet ring's retire timer counts whole milliseconds, up to its own longest: the
    // budget said is the one it keeps.
    if (ro.packet_ring) {
      constexpr std::int64_t kMs = kNsPerMillisecond;
      ro.latency_budget_ns = std::clamp<std::int64_t>(ro.latency_budget_ns / kMs * kMs, kMs,
                                                      PacketRingReceiver::kMaxRetireMs * kMs);
    }
  }
  return ro;
}

ReplayOptions replay_options(const DaemonConfig& config, const RunSource& source) {
  ReplayOptions ro;
  ro.path = source.replay_path;
  ro.rate = source.rate;
  if (source.port_given) ro.destination_port = config.sensor.data_port;
  ro.sensor_ip = config.sensor.sensor_ip;
  return ro;
}

std::optional<PtcClientOptions> ptc_client_options(const DaemonConfig& config,
                                                   const RunSource& source,
                                                   std::uint16_t simulated_ptc_port) {
  const SensorSection& s = config.sensor;
  PtcClientOptions o;
  o.port = s.ptc_port;
  o.timeout = std::chrono::milliseconds(s.ptc_timeout_ms);
  switch (source.kind) {
    case RunSource::Kind::kSimulated:
      o.address = "127.0.0.1";
      if (!source.ptc_port_given) o.port = simulated_ptc_port;
      return o;
    case RunSource::Kind::kReplay:
      if (s.calibration_source != "sensor") return std::nullopt;
      break;
    case RunSource::Kind::kLive:
      break;
  }
  if (s.sensor_ip.empty()) return std::nullopt;
  o.address = s.sensor_ip;
  return o;
}

bool status_polled(const DaemonConfig& config, const RunSource& source,
                   const std::optional<PtcClientOptions>& ptc) {
  return ptc && source.kind != RunSource::Kind::kReplay &&
         config.sensor.status_interval_seconds > 0;
}

SyntheticSensorConfig simulated_sensor_config(const RunSource& source, std::int64_t start_unix_ns) {
  SyntheticSensorConfig sc;
  sc.rpm = source.simulated_rpm;
  sc.return_mode = source.simulated_mode;
  sc.udp_sequence = source.simulated_udp_sequence;
  sc.start_unix_ns = start_unix_ns;
  return sc;
}

live::LiveOptions live_options(const DaemonConfig& config, std::string_view version,
                               std::optional<SensorModelId> model) {
  live::LiveOptions o;
  o.address = config.live.address;
  o.port = config.live.port;
  o.max_clients = config.live.max_clients;
#ifdef PANDARCAP_TEST_HOOKS
  // Test hook: a port in use tried again this often (ms), so a test need not wait 10 s.
  if (const char* retry = std::getenv("PANDARCAP_TEST_LIVE_RETRY_MS"))
    o.listen_retry_ms = static_cast<std::uint32_t>(std::strtoul(retry, nullptr, 10));
#endif
  o.name = fmt::format("pandarcap {} ({})", version, sensor_label(config, std::nullopt));
  o.points_topic = config.output.mcap_points_topic;
  o.health_topic = config.output.mcap_health_topic;
  o.points_schema_name = std::string(mcap::kPointCloud2Name);
  o.points_schema = std::string(mcap::kPointCloud2Schema);
  o.health_schema = std::string(kHealthJsonSchema);
  // Two of the largest frames queued per viewer (one being written, one waiting), and room for
  // the health and status messages beside them.
  o.client_queue_bytes = 2 * live_points_capacity(config, model) + live::kHealthMessageCapacity;
  return o;
}

std::size_t live_points_capacity(const DaemonConfig& config, std::optional<SensorModelId> model) {
  // The arenas' points (arena_points), not arenas.points_per_frame: a frame that fills its arena
  // must fit the hand-over and a viewer's queue, or the live view drops every frame.
  return live::points_message_bytes(pcd_format(config).layout, config.output.mcap_frame_id.size(),
                                    arena_points(config, model));
}

}  // namespace pandarcap
