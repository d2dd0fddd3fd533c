#include "core/progress_line.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

namespace pandarcap {

std::optional<std::string> ProgressLine::update(double elapsed_s, std::uint64_t done_bytes,
                                                std::uint64_t total_bytes, std::uint64_t packets) {
  if (elapsed_s < quiet_s_ || total_bytes == 0) return std::nullopt;
  if (last_s_ >= 0 && elapsed_s - last_s_ < interval_s_) return std::nullopt;
  last_s_ = elapsed_s;
  shown_ = true;
  const std::uint64_t done = std::min(done_bytes, total_bytes);
  const double fraction = static_cast<double>(done) / static_cast<double>(total_bytes);
  std::string line =
      fmt::format("replay: {:.0f}% ({:.1f} of {:.1f} MB), {:.0f} packets/s",
                  std::floor(fraction * 100), static_cast<double>(done) / 1e6,
                  static_cast<double>(total_bytes) / 1e6, static_cast<double>(packets) / elapsed_s);
  if (fraction > 0) {
    const double left_s = elapsed_s * (1 - fraction) / fraction;
    line += left_s >= 120 ? fmt::format(", {:.0f} min left", left_s / 60)
                          : fmt::format(", {:.0f} s left", left_s);
  }
  return line;
}

}  // namespace pandarcap
