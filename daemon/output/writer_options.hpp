// The writer thread's configuration (from the config file's output and health sections), shared
// by its parts: frame output, pcap recording, health publishing. Plain data.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "core/frames/pcd.hpp"
#include "core/health/health.hpp"
#include "core/sensors/sensor_model_id.hpp"
#include "daemon/mcap/mcap_file_options.hpp"
#include "daemon/pcap/capture_reader.hpp"

namespace pandarcap {

struct WriterOptions {
  std::filesystem::path output_dir;       // frames/, raw/ and mcap/ go under it
  std::filesystem::path health_dir;       // health.jsonl
  std::filesystem::path prometheus_file;  // the .prom textfile
  bool frames = true;
  // The decoder decodes points and cuts frames (daemon_options.hpp, points_decoded()); false:
  // the health leaves the point and frame counters out.
  bool points_counted = true;
  PcdFormat pcd_format;  // output.pcd_fields and sensor.frame (the arenas, PCD and MCAP)
  std::uint64_t frames_max_files = 0;
  std::uint64_t frames_max_bytes = 0;
  bool pcd_lzf = false;  // output.pcd_compression = "lzf": DATA binary_compressed
  // arenas.points_per_frame: the largest frame, which the compressed frames' buffers are sized
  // for at start-up (0: sized by the first frames, allocating then).
  std::size_t max_frame_points = 0;
  bool pcap = true;
  std::uint64_t pcap_rotate_bytes = 0;
  std::uint32_t pcap_rotate_seconds = 0;
  std::uint64_t pcap_max_files = 0;
  std::uint64_t pcap_max_bytes = 0;
  bool pcap_zstd = false;  // output.pcap_compression = "zstd": raw/NAME.pcap.zst
  int pcap_zstd_level = 1;
  bool mcap = false;
  std::uint64_t mcap_rotate_bytes = 0;
  std::uint32_t mcap_rotate_seconds = 0;
  std::uint64_t mcap_max_files = 0;
  std::uint64_t mcap_max_bytes = 0;
  // Health messages take the latest frame's or packet's time (a replay), not the host's clock.
  bool mcap_replay_time = false;
  McapFileOptions mcap_file;
  // The floor of free space on each output file system (the larger of the two; 0 = none).
  std::uint64_t min_free_bytes = 0;
  double min_free_percent = 0;
  // A recording being written and health.jsonl are synced this often (0: only when finished).
  double sync_interval_seconds = 2.0;
  // output.upload: raw/ and mcap/ leave by upload (frames/ too with upload_frames).
  bool upload = false;
  bool upload_frames = false;
  bool prometheus = true;
  bool jsonl = true;
  // Where the health files go while health_dir (or the .prom's directory) cannot be written: the
  // first of these that takes them (health.fallback_directory, then the defaults).
  std::vector<std::filesystem::path> health_fallback_dirs;
  std::uint64_t jsonl_rotate_bytes = 0;
  std::string sensor_name;
  // The label is the decoded model's name, which the packets choose (a live "auto" with no
  // health.sensor_name): the health follows the decode worker's model.
  bool sensor_name_from_model = false;
  // What names the model besides the packets (health_policy.hpp, HealthExpectations): the
  // calibration's channels at start, the lasers the PTC inventory reports (0: none).
  int calibration_channels = 0;
  int inventory_lasers = 0;
  std::string version;
  std::string decoder;  // decoder target in use, reported in the health output
  double no_data_timeout_seconds = 1.0;
  double min_hours_left = 0;  // fewer hours of disk left: degraded; 0 = not checked
  double max_sensor_clock_offset_seconds = 1.0;  // further off is degraded; 0 = not checked
  std::string expected_return_mode = "any";
  int expected_rpm = 600;
  std::string calibration_csv;
  // A live "auto": the table each model's decoder would use (indexed by SensorModelId), which
  // replaces calibration_csv when the packets name that model. Empty otherwise.
  std::array<std::string, kSensorModelIds.size()> calibration_by_model;
  SensorModelId calibration_model = SensorModelId::kPandar40P;  // calibration_csv's
  // The sensor's identity and the calibration's source (pandarcap_sensor_info), and the
  // neighbour file raw/sensor.json saved beside the recordings (daemon/ptc/sensor_at_start.hpp).
  SensorIdentity sensor_identity;
  std::string sensor_json;
  // output.device_name resolved (the host name when unset), and the effective configuration's
  // hash (daemon_options.hpp, config_hash): in every MCAP file's metadata and in sensor.json.
  std::string device_name;
  std::string config_hash;
  // The sensor's status is polled over PTC every status_interval_seconds (status_polled).
  bool status_polled = false;
  double status_interval_seconds = 0;
  // Test hook (PANDARCAP_TEST_STALL_WRITER_FILE): while this file exists, the writer stops at its
  // next once-a-second tick, without a heartbeat, as a writer stuck on a dead disk would. Lets
  // the tests see the watchdog stop and frames drop (counted) behind a stalled writer. "" = off.
  std::string test_stall_file;
};

}  // namespace pandarcap
