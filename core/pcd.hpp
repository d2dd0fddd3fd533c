// Frames as PCD v0.7 binary files, the Point Cloud Library's format (pcl_viewer, CloudCompare,
// Open3D and ROS tools read it).
//
// Fields, packed with no padding (23 bytes a point, little-endian):
//   x y z        F4  metres, sensor frame
//   intensity    U1  reflectivity byte
//   channel      U1  0..39
//   return_type  U1  0 single, 1 last, 2 strongest, 3 last and strongest merged
//   timestamp    F8  firing time, seconds since the Unix epoch (double: ~0.24 µs resolution)
// The header keys come in the order PCL writes and expects them; an unordered cloud has
// WIDTH = POINTS and HEIGHT = 1.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

#include "point.hpp"

namespace pandarcap {

inline constexpr std::size_t kPcdPointBytes = 3 * 4 + 3 * 1 + 8;  // 23

// The ASCII header for `points` points, ending with "DATA binary\n".
std::string pcd_header(std::size_t points);
// The same, appended to `out` (no allocation once `out` has room for it).
void append_pcd_header(std::string& out, std::size_t points);

// Encodes points into `out` (which must hold points.size() * kPcdPointBytes bytes) and returns
// the bytes written. No allocation.
std::size_t encode_pcd_points(std::span<const Point> points, std::span<std::uint8_t> out) noexcept;

// The fields of one encoded point, for tests and tools reading the files back.
struct PcdPoint {
  float x = 0, y = 0, z = 0;
  std::uint8_t intensity = 0, channel = 0, return_type = 0;
  double timestamp_s = 0;
};
PcdPoint decode_pcd_point(std::span<const std::uint8_t, kPcdPointBytes> bytes) noexcept;

}  // namespace pandarcap
