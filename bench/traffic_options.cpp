#include "bench/traffic_options.hpp"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <type_traits>
#include <vector>

#include "core/sensors/sensor_models.hpp"

namespace pandarcap::bench {

bool parse_traffic_option(CliArgs& args, std::string_view arg, GeneratorOptions& traffic,
                          SyntheticSensorConfig& sensor, std::string& capture) {
  if (arg == "--capture") {
    capture = std::string(args.value(arg));
  } else if (arg == "--rpm") {
    sensor.rpm = static_cast<int>(args.integer(arg, 1, 100'000));
  } else if (arg == "--return-mode") {
    const std::string_view name = args.value(arg);
    // "single" is what people call the sensor's default single-return setting: strongest.
    const auto mode = name == "single" ? ReturnMode::kStrongest : return_mode_from_string(name);
    if (!mode) {
      args.usage_error(fmt::format(
          "--return-mode is dual, single (= strongest), strongest, last, first, first_last or "
          "first_strongest, got '{}'",
          name));
    }
    sensor.return_mode = *mode;
  } else if (arg == "--burst-factor") {
    traffic.burst_factor = args.number(arg, 1, 1000);
  } else if (arg == "--burst-ms") {
    traffic.burst_ms = args.number(arg, 0, 60'000);
  } else if (arg == "--burst-every") {
    traffic.burst_every_s = args.number(arg, 0.001, 3600);
  } else if (arg == "--foreign-fraction") {
    traffic.foreign_fraction = args.number(arg, 0, 10);
  } else if (arg == "--malformed-fraction") {
    traffic.malformed_fraction = args.number(arg, 0, 10);
  } else if (arg == "--duplicate-fraction") {
    traffic.duplicate_fraction = args.number(arg, 0, 1);
  } else if (arg == "--glitch-fraction") {
    traffic.glitch_fraction = args.number(arg, 0, 1);
  } else if (arg == "--clock-start") {
    // 2000-01-01 .. 2099: what the tail's date can carry.
    traffic.clock_start_unix_ns =
        static_cast<std::int64_t>(args.number(arg, 946'684'800, 4'102'444'799) * 1e9);
  } else {
    return false;
  }
  return true;
}

std::optional<std::string> sensor_problem(SensorModelId model,
                                          const SyntheticSensorConfig& sensor) {
  return with_model(model, [&]<class M>(std::type_identity<M>) -> std::optional<std::string> {
    const auto& rpms = M::kSupportedRpms;
    if (std::find(rpms.begin(), rpms.end(), sensor.rpm) == rpms.end()) {
      return fmt::format("--rpm: the {} turns at {} RPM, got {}", display_name(model),
                         fmt::join(rpms, " or "), sensor.rpm);
    }
    const auto& modes = M::kReturnModes;
    if (std::find(modes.begin(), modes.end(), sensor.return_mode) == modes.end()) {
      std::vector<std::string_view> names;
      for (const ReturnMode mode : modes)
        names.push_back(to_string(mode));
      return fmt::format("--return-mode: the {} sends {} (single = strongest), got '{}'",
                         display_name(model), fmt::join(names, ", "),
                         to_string(sensor.return_mode));
    }
    return std::nullopt;
  });
}

}  // namespace pandarcap::bench
