#include "config/command_line.hpp"

#include "config/config_loader.hpp"

namespace pandarcap {

const KeyOption* find_key_option(std::string_view option) noexcept {
  for (const KeyOption& entry : kKeyOptions) {
    if (entry.option == option) return &entry;
  }
  return nullptr;
}

std::optional<std::string> key_option_problem(const KeyOption& option, std::string_view text) {
  DaemonConfig probe;
  try {
    set_config_value(probe, option.key, text, std::string(option.option));
  } catch (const ConfigError& error) {
    return std::string(error.what());
  }
  return std::nullopt;
}

StreamDecoderConfig stream_decoder_config(const DaemonConfig& config) {
  StreamDecoderConfig decode;
  decode.decoder.min_range_m = config.sensor.min_range;
  decode.decoder.max_range_m = config.sensor.max_range;
  decode.decoder.dual_return_distance_threshold_m = config.sensor.dual_return_distance_threshold;
  decode.decoder.firing_time_correction = config.sensor.firing_time_correction;
  decode.cut_angle_deg = config.sensor.cut_angle;
  return decode;
}

}  // namespace pandarcap
