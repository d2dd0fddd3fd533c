// Per-channel angle calibration: elevation and azimuth offset of each laser of a model (spec §3):
// 40 for the Pandar40P, 64, 32, 16 or 128 for the others (core/sensors/sensor_models.hpp).
//
// File format (Hesai "angle correction" CSV, the same text the sensor serves on TCP port 9347):
//
//   Laser id,Elevation,Azimuth        <- one header line; its text varies and is ignored
//   1,14.794,-1.042                   <- id 1..N, degrees, elevation up-positive,
//   ...                                  azimuth offset clockwise-positive, ADDED to block azimuth
//
// CRLF or LF line endings, with or without a newline after the last row, blank lines ignored.
// Every channel of the model must appear exactly once, and no other; anything else is a
// CalibrationError whose message starts with "file:line:col: " and names the count expected
// ("expected 64 channels (Pandar64), found 40: ...").
//
// Without a file the model's nominal table is used (its header says which table that is); per-
// unit files differ from it by up to ~0.45° in elevation, so callers should log that the nominal
// table is in use.
#pragma once

#include <array>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>

#include "core/sensors/packet.hpp"
#include "core/sensors/sensor_model_id.hpp"

namespace pandarcap {

class CalibrationError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct Calibration {
  // Channels 0 .. channel_count - 1 hold the table; the rest stay 0.
  std::array<double, kMaxChannels> elevation_deg{};
  std::array<double, kMaxChannels> azimuth_offset_deg{};
  int channel_count = kChannels;  // the model's: 40 for the Pandar40P
  std::string source;             // "nominal" or the file it was loaded from

  // The model's nominal table (the Pandar40P's: its design table, +15° ... -25°; offsets
  // -1.042 / +3.125 / -5.208°).
  static Calibration nominal(SensorModelId model = SensorModelId::kPandar40P);
  // Parses CSV text holding exactly the model's channels. `source_name` is used in error
  // messages and stored in `source`.
  static Calibration parse(std::string_view text, const std::string& source_name,
                           SensorModelId model = SensorModelId::kPandar40P);

  // The same for a model not yet known ("auto"): the table's row count names it (40, 64, 32, 16
  // or 128 channels); other counts are read as the Pandar40P's, whose error says what was found.
  static Calibration parse_any(std::string_view text, const std::string& source_name);
  // parse() for `model`, parse_any() for none.
  static Calibration parse_for(std::string_view text, const std::string& source_name,
                               std::optional<SensorModelId> model) {
    return model ? parse(text, source_name, *model) : parse_any(text, source_name);
  }
  // The model a table is for, by its channel count (the Pandar40P for 40).
  SensorModelId model() const noexcept;

  bool is_nominal() const noexcept { return source == "nominal"; }
  // The table as CSV in the same format (saved next to recordings).
  std::string to_csv() const;
};

}  // namespace pandarcap
