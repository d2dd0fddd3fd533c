// Per-channel angle calibration: elevation and azimuth offset of each of the 40 lasers (spec §3).
//
// File format (Hesai "angle correction" CSV, the same text the sensor serves on TCP port 9347):
//
//   Laser id,Elevation,Azimuth        <- one header line; its text varies and is ignored
//   1,14.794,-1.042                   <- id 1..40, degrees, elevation up-positive,
//   ...                                  azimuth offset clockwise-positive, ADDED to block azimuth
//
// CRLF or LF line endings, with or without a newline after the last row, blank lines ignored.
// Every channel must appear exactly once; anything else is a CalibrationError whose message
// starts with "file:line:col: ".
//
// Without a file the nominal (design) table of the Pandar40P is used; per-unit files differ from
// it by up to ~0.45° in elevation, so callers should log that the nominal table is in use.
#pragma once

#include <array>
#include <stdexcept>
#include <string>
#include <string_view>

#include "core/sensors/packet.hpp"

namespace pandarcap {

class CalibrationError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct Calibration {
  std::array<double, kChannels> elevation_deg{};
  std::array<double, kChannels> azimuth_offset_deg{};
  std::string source;  // "nominal" or the file it was loaded from

  // The Pandar40P design table (+15° ... -25°; offsets -1.042 / +3.125 / -5.208°).
  static Calibration nominal();
  // Parses CSV text. `source_name` is used in error messages and stored in `source`.
  static Calibration parse(std::string_view text, const std::string& source_name);

  bool is_nominal() const noexcept { return source == "nominal"; }
  // The table as CSV in the same format (saved next to recordings).
  std::string to_csv() const;
};

}  // namespace pandarcap
