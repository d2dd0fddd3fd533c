#include "daemon/io/calibration_file.hpp"

#include <fmt/format.h>

#include "daemon/io/text_file.hpp"

namespace pandarcap {

Calibration load_calibration(const std::string& path, std::optional<SensorModelId> model) {
  const TextFile file = read_text_file(path);
  switch (file.status) {
    case TextFile::Status::kOk:
      break;
    case TextFile::Status::kCannotOpen:
      throw CalibrationError(fmt::format("{}: cannot open calibration file", path));
    case TextFile::Status::kNotRegular:
      throw CalibrationError(
          fmt::format("{}: not a regular file (a FIFO, socket, device or directory): not a "
                      "calibration table",
                      path));
    case TextFile::Status::kCannotRead:
      throw CalibrationError(fmt::format("{}: cannot read calibration file", path));
    case TextFile::Status::kTooLarge:
      throw CalibrationError(fmt::format("{}:1:1: larger than {} bytes: not a calibration table",
                                         path, kMaxOperatorFileBytes));
  }
  return Calibration::parse_for(file.text, path, model);
}

}  // namespace pandarcap
