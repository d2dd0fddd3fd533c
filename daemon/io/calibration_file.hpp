// A calibration file the operator names (sensor.calibration_file, --calibration, a recording's
// sidecar), read and parsed: core/decode/calibration.hpp parses text; reading it is this layer's.
#pragma once

#include <string>

#include "core/decode/calibration.hpp"

namespace pandarcap {

// Reads and parses `path` (bounded: read_text_file); an unreadable file, or one that is not a
// regular file, is a CalibrationError naming it, as a malformed one is (file:line:col).
// `model`: the table must have that model's channels; none: any supported model's count.
Calibration load_calibration(const std::string& path,
                             std::optional<SensorModelId> model = SensorModelId::kPandar40P);

}  // namespace pandarcap
