// The PTC answers as JSON, one spelling for pandarcap-ctl --json and raw/sensor.json.
#pragma once

#include <nlohmann/json.hpp>

#include "core/decode/calibration.hpp"
#include "core/ptc/ptc_messages.hpp"

namespace pandarcap {

nlohmann::ordered_json to_json(const ptc::SensorInventory& inventory);
nlohmann::ordered_json to_json(const ptc::SensorSettings& settings);
// Temperatures in °C, the PTP state and clock names spelt out ("locked").
nlohmann::ordered_json to_json(const ptc::SensorStatus& status);
// {"channels": [{"channel": 1, "elevation_deg": ..., "azimuth_offset_deg": ...}, ...]}
nlohmann::ordered_json to_json(const Calibration& calibration);

}  // namespace pandarcap
