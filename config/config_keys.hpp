// The configuration's keys: each one's table, name, member of DaemonConfig and check, stated
// once. Reading a file, checking values, setting a key from a command-line option, the
// unknown-key check and --print-config all walk this one list, so they cannot drift apart:
// adding a key means adding one line here (and its default in daemon_config.hpp, its
// documentation in pandarcap.toml). Internal to config/.
#pragma once

#include <fmt/format.h>

#include <cstdint>
#include <limits>
#include <string>
#include <string_view>
#include <variant>

#include "config/value_checks.hpp"

namespace pandarcap::config_detail {

// Calls `v` once per configuration key, in the order of config/pandarcap.toml:
//   v(table, key, member, check)
// where `check` is an IntRange, a RealRange, a StringCheck, or nothing for booleans.
// Table "" is the document's top level.
template <typename Config, typename Visitor>
inline void for_each_key(Config& c, Visitor&& v) {
  constexpr std::int64_t kU32 = std::numeric_limits<std::uint32_t>::max();
  constexpr std::int64_t kI64 = std::numeric_limits<std::int64_t>::max();
  constexpr std::int64_t kMaxCpu = 1023;  // CPU_SETSIZE - 1
  v("", "log_level", c.log_level, &log_level);
  v("", "decoder", c.decoder, &decoder_name);

  auto& s = c.sensor;
  v("sensor", "sensor_ip", s.sensor_ip, &ipv4_or_empty);
  v("sensor", "host_ip", s.host_ip, &ipv4);
  v("sensor", "multicast_ip", s.multicast_ip, &multicast_or_empty);
  v("sensor", "multicast_interface_ip", s.multicast_interface_ip, &ipv4_or_empty);
  v("sensor", "interface", s.interface, &interface_or_empty);
  v("sensor", "data_port", s.data_port, IntRange{1, 65535});
  v("sensor", "udp_socket_receive_buffer_size_bytes", s.udp_socket_receive_buffer_size_bytes,
    IntRange{0, std::numeric_limits<std::int32_t>::max()});
  v("sensor", "model", s.model, &sensor_model);
  v("sensor", "return_mode", s.return_mode, &return_mode);
  v("sensor", "rotation_speed", s.rotation_speed, IntRange{600, 1200});
  v("sensor", "cut_angle", s.cut_angle, RealRange{0.0, false, 360.0, true});
  v("sensor", "min_range", s.min_range, RealRange{0.0, false, kNoUpperBound, false});
  v("sensor", "max_range", s.max_range, RealRange{0.0, true, kNoUpperBound, false});
  v("sensor", "dual_return_distance_threshold", s.dual_return_distance_threshold,
    RealRange{0.0, false, kNoUpperBound, false});
  v("sensor", "calibration_file", s.calibration_file, &any_string);
  v("sensor", "firing_time_correction", s.firing_time_correction, std::monostate{});
  v("sensor", "calibration_source", s.calibration_source, &calibration_source);
  v("sensor", "frame", s.frame, &axes);
  v("sensor", "ptc_port", s.ptc_port, IntRange{1, 65535});
  v("sensor", "ptc_timeout_ms", s.ptc_timeout_ms, IntRange{100, 60'000});
  v("sensor", "status_interval_seconds", s.status_interval_seconds,
    RealRange{0.0, false, 3600.0, false});

  v("input", "receiver", c.input.receiver, &receiver);

  v("ring", "slots", c.ring.slots, IntRange{64, 1 << 20});
  v("ring", "receive_batch", c.ring.receive_batch, IntRange{1, 1024});

  v("arenas", "count", c.arenas.count, IntRange{2, 64});
  v("arenas", "points_per_frame", c.arenas.points_per_frame, IntRange{1000, 10'000'000});
  v("arenas", "packets_per_frame", c.arenas.packets_per_frame, IntRange{1, 65536});

  auto& o = c.output;
  v("output", "directory", o.directory, &non_empty);
  v("output", "device_name", o.device_name, &device_name);
  v("output", "frames", o.frames, std::monostate{});
  v("output", "pcd_fields", o.pcd_fields, &pcd_fields);
  v("output", "pcd_compression", o.pcd_compression, &pcd_compression);
  v("output", "frame_decimation", o.frame_decimation, IntRange{1, kU32});
  v("output", "frames_min_fraction", o.frames_min_fraction, RealRange{0.0, false, 1.0, false});
  v("output", "frames_max_files", o.frames_max_files, IntRange{0, kI64});
  v("output", "frames_max_bytes", o.frames_max_bytes, IntRange{0, kI64});
  v("output", "pcap", o.pcap, std::monostate{});
  v("output", "pcap_rotate_bytes", o.pcap_rotate_bytes, IntRange{0, kI64});
  v("output", "pcap_rotate_seconds", o.pcap_rotate_seconds, IntRange{0, kU32});
  v("output", "pcap_max_files", o.pcap_max_files, IntRange{0, kI64});
  v("output", "pcap_max_bytes", o.pcap_max_bytes, IntRange{0, kI64});
  v("output", "pcap_compression", o.pcap_compression, &pcap_compression);
  v("output", "pcap_compression_level", o.pcap_compression_level, IntRange{-7, 19});
  v("output", "mcap", o.mcap, std::monostate{});
  v("output", "mcap_packets", o.mcap_packets, std::monostate{});
  v("output", "mcap_compression", o.mcap_compression, &mcap_compression);
  v("output", "mcap_compression_level", o.mcap_compression_level, IntRange{-7, 19});
  v("output", "mcap_chunk_bytes", o.mcap_chunk_bytes, IntRange{64 * 1024, 256 << 20});
  v("output", "mcap_chunk_crc", o.mcap_chunk_crc, std::monostate{});
  v("output", "mcap_rotate_bytes", o.mcap_rotate_bytes, IntRange{0, kI64});
  v("output", "mcap_rotate_seconds", o.mcap_rotate_seconds, IntRange{0, kU32});
  v("output", "mcap_max_files", o.mcap_max_files, IntRange{0, kI64});
  v("output", "mcap_max_bytes", o.mcap_max_bytes, IntRange{0, kI64});
  v("output", "mcap_frame_id", o.mcap_frame_id, &frame_id);
  v("output", "mcap_points_topic", o.mcap_points_topic, &topic);
  v("output", "mcap_health_topic", o.mcap_health_topic, &topic);
  v("output", "mcap_packets_topic", o.mcap_packets_topic, &topic);
  v("output", "min_free_bytes", o.min_free_bytes, IntRange{0, kI64});
  v("output", "min_free_percent", o.min_free_percent, RealRange{0.0, false, 90.0, false});
  v("output", "sync_interval_seconds", o.sync_interval_seconds,
    RealRange{0.0, false, 3600.0, false});
  v("output", "upload", o.upload, std::monostate{});
  v("output", "upload_frames", o.upload_frames, std::monostate{});

  auto& h = c.health;
  v("health", "sensor_name", h.sensor_name, &label_or_empty);
  v("health", "no_data_timeout_seconds", h.no_data_timeout_seconds,
    RealRange{0.0, true, 86400.0, false});
  v("health", "max_sensor_clock_offset_seconds", h.max_sensor_clock_offset_seconds,
    RealRange{0.0, false, kNoUpperBound, true});
  v("health", "prometheus", h.prometheus, std::monostate{});
  v("health", "jsonl", h.jsonl, std::monostate{});
  v("health", "jsonl_rotate_bytes", h.jsonl_rotate_bytes, IntRange{0, kI64});
  v("health", "directory", h.directory, &any_string);
  v("health", "prometheus_file", h.prometheus_file, &prom_file_or_empty);
  v("health", "min_hours_left", h.min_hours_left, RealRange{0.0, false, 100'000.0, false});
  v("health", "fallback_directory", h.fallback_directory, &any_string);

  auto& t = c.threads;
  v("threads", "receive_cpu", t.receive_cpu, IntRange{-1, kMaxCpu});
  v("threads", "decode_cpu", t.decode_cpu, IntRange{-1, kMaxCpu});
  v("threads", "writer_cpu", t.writer_cpu, IntRange{-1, kMaxCpu});
  v("threads", "receive_priority", t.receive_priority, IntRange{0, 99});
  v("threads", "decode_priority", t.decode_priority, IntRange{0, 99});
  v("threads", "writer_priority", t.writer_priority, IntRange{0, 99});
  v("threads", "lock_memory", t.lock_memory, std::monostate{});

  v("latency", "budget_ms", c.latency.budget_ms, IntRange{0, 1000});

  v("live", "foxglove", c.live.foxglove, std::monostate{});
  v("live", "address", c.live.address, &ipv4);
  v("live", "port", c.live.port, IntRange{1, 65535});
  v("live", "max_clients", c.live.max_clients, IntRange{1, 64});
}

// "sensor.data_port"; a top-level key is its name alone.
inline std::string dotted(std::string_view table, std::string_view key) {
  return table.empty() ? std::string(key) : fmt::format("{}.{}", table, key);
}

}  // namespace pandarcap::config_detail
