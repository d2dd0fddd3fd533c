// One decoded point, as the decoders write it and frames store it.
#pragma once

#include <cstdint>
#include <string_view>

namespace pandarcap {

// Which echo of a firing a point is.
enum class ReturnType : std::uint8_t {
  kSingle = 0,         // single-return mode: the frame's return mode says strongest or last
  kLast = 1,           // dual mode, even block of the pair
  kStrongest = 2,      // dual mode, odd block of the pair (strongest, or second strongest)
  kLastStrongest = 3,  // dual mode, both echoes coincide and were merged into this one point
};
std::string_view to_string(ReturnType type) noexcept;

// 32 bytes, no padding surprises: stored as-is in frame arenas.
struct Point {
  float x = 0, y = 0, z = 0;       // metres, sensor frame: z up, y at azimuth 0, x at 90°
  float distance_m = 0;            // range along the beam
  std::int64_t timestamp_ns = 0;   // firing time, ns since the Unix epoch (see PacketTime)
  std::uint16_t azimuth_cdeg = 0;  // corrected azimuth, 0.01°, 0..35999
  std::uint8_t intensity = 0;      // reflectivity byte
  std::uint8_t channel = 0;        // 0..39 (manual channel number - 1)
  ReturnType return_type = ReturnType::kSingle;
  std::uint8_t reserved_[3]{};
};
static_assert(sizeof(Point) == 32, "Point is stored in arenas and files; keep it 32 bytes");

}  // namespace pandarcap
