// The command-line options that set configuration keys, stated once for pandarcapd and
// pandarcap-inspect.
//
// Each option is the key's name on a command line; its type and range are the configuration
// file's (set_config_value in config_loader.hpp), so `--max-range 0` is refused with the same
// words, for the same reason, as `max_range = 0` in a file.
#pragma once

#include <array>
#include <optional>
#include <string>
#include <string_view>

#include "config/daemon_config.hpp"
#include "core/decode/stream_decoder.hpp"

namespace pandarcap {

struct KeyOption {
  std::string_view option;  // "--max-range"
  std::string_view key;     // "sensor.max_range"
  bool flag = false;        // takes no value: sets the (boolean) key to true
};

inline constexpr std::array kKeyOptions{
    KeyOption{"--output-dir", "output.directory"},
    KeyOption{"--calibration", "sensor.calibration_file"},
    KeyOption{"--calibration-source", "sensor.calibration_source"},
    KeyOption{"--ptc-port", "sensor.ptc_port"},
    KeyOption{"--status-interval", "sensor.status_interval_seconds"},
    KeyOption{"--host-ip", "sensor.host_ip"},
    KeyOption{"--port", "sensor.data_port"},
    KeyOption{"--receiver", "input.receiver"},
    KeyOption{"--interface", "sensor.interface"},
    KeyOption{"--sensor-ip", "sensor.sensor_ip"},
    KeyOption{"--cut-angle", "sensor.cut_angle"},
    KeyOption{"--frame", "sensor.frame"},
    KeyOption{"--pcd-fields", "output.pcd_fields"},
    KeyOption{"--pcd-compression", "output.pcd_compression"},
    KeyOption{"--pcap-compression", "output.pcap_compression"},
    KeyOption{"--min-free-bytes", "output.min_free_bytes"},
    KeyOption{"--upload", "output.upload", true},
    KeyOption{"--upload-frames", "output.upload_frames", true},
    KeyOption{"--min-range", "sensor.min_range"},
    KeyOption{"--max-range", "sensor.max_range"},
    KeyOption{"--dual-return-distance-threshold", "sensor.dual_return_distance_threshold"},
    KeyOption{"--firing-time-correction", "sensor.firing_time_correction", true},
    KeyOption{"--rpm", "sensor.rotation_speed"},
    KeyOption{"--return-mode", "sensor.return_mode"},
    KeyOption{"--sensor-model", "sensor.model"},
    KeyOption{"--mcap", "output.mcap", true},
    KeyOption{"--mcap-packets", "output.mcap_packets", true},
    KeyOption{"--mcap-compression", "output.mcap_compression"},
    KeyOption{"--decoder", "decoder"},
    KeyOption{"--latency-budget-ms", "latency.budget_ms"},
    KeyOption{"--log-level", "log_level"},
    KeyOption{"--max-clock-offset", "health.max_sensor_clock_offset_seconds"},
};

// The entry for `option`, or null when it sets no key.
const KeyOption* find_key_option(std::string_view option) noexcept;

// Checks `text` for `option`'s key as set_config_value would, on a default configuration:
// the problem in words ("sensor.max_range: 0 is out of range (> 0)"), or nothing when it is
// fine. For a parser that reports bad options at once (exit 64) rather than after loading.
std::optional<std::string> key_option_problem(const KeyOption& option, std::string_view text);

// What a configuration means for the stream decoder: ranges, dual-return threshold, firing-time
// correction and cut angle (the decoder target is the caller's: "auto" is resolved at start-up).
// One mapping for the daemon and pandarcap-inspect, so both decode a capture the same way.
StreamDecoderConfig stream_decoder_config(const DaemonConfig& config);

}  // namespace pandarcap
