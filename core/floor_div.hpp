// Integer division rounded toward minus infinity. C++'s `/` rounds toward zero, so an azimuth
// position before the origin would otherwise fall into the cell or revolution after its own.
#pragma once

#include <cstdint>

namespace pandarcap {

constexpr std::int64_t floor_div(std::int64_t a, std::int64_t b) noexcept {
  const std::int64_t q = a / b;
  return (a % b != 0 && (a < 0) != (b < 0)) ? q - 1 : q;
}

}  // namespace pandarcap
