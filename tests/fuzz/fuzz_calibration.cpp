// Fuzz target: the calibration CSV loader. Any input either parses into 40 finite angles or
// throws CalibrationError with a location; anything else (another exception, a crash, UB) fails.
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string_view>

#include "core/decode/calibration.hpp"

using namespace pandarcap;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  try {
    const Calibration calibration = Calibration::parse(text, "fuzz.csv");
    // What it parsed prints and parses back to the same table.
    const Calibration again = Calibration::parse(calibration.to_csv(), "again.csv");
    if (again.to_csv() != calibration.to_csv()) std::abort();
  } catch (const CalibrationError&) {
  }
  return 0;
}
