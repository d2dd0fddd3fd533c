#include "pcd.hpp"

#include <fmt/format.h>

#include <bit>
#include <cassert>
#include <cstring>

namespace pandarcap {

static_assert(std::endian::native == std::endian::little,
              "PCD binary data is written in host order; readers assume little-endian");

std::string pcd_header(std::size_t points) {
  std::string out;
  append_pcd_header(out, points);
  return out;
}

void append_pcd_header(std::string& out, std::size_t points) {
  fmt::format_to(std::back_inserter(out),
                 "# .PCD v0.7 - Point Cloud Data file format\n"
                 "VERSION 0.7\n"
                 "FIELDS x y z intensity channel return_type timestamp\n"
                 "SIZE 4 4 4 1 1 1 8\n"
                 "TYPE F F F U U U F\n"
                 "COUNT 1 1 1 1 1 1 1\n"
                 "WIDTH {}\n"
                 "HEIGHT 1\n"
                 "VIEWPOINT 0 0 0 1 0 0 0\n"
                 "POINTS {}\n"
                 "DATA binary\n",
                 points, points);
}

std::size_t encode_pcd_points(std::span<const Point> points, std::span<std::uint8_t> out) noexcept {
  assert(out.size() >= points.size() * kPcdPointBytes);
  std::uint8_t* p = out.data();
  for (const Point& point : points) {
    std::memcpy(p, &point.x, 4);
    std::memcpy(p + 4, &point.y, 4);
    std::memcpy(p + 8, &point.z, 4);
    p[12] = point.intensity;
    p[13] = point.channel;
    p[14] = static_cast<std::uint8_t>(point.return_type);
    // Split into whole seconds and the rest before converting, so the double keeps all it can.
    const std::int64_t whole = point.timestamp_ns / 1'000'000'000;
    const std::int64_t rest = point.timestamp_ns % 1'000'000'000;
    const double seconds = static_cast<double>(whole) + static_cast<double>(rest) * 1e-9;
    std::memcpy(p + 15, &seconds, 8);
    p += kPcdPointBytes;
  }
  return static_cast<std::size_t>(p - out.data());
}

PcdPoint decode_pcd_point(std::span<const std::uint8_t, kPcdPointBytes> bytes) noexcept {
  PcdPoint point;
  const std::uint8_t* p = bytes.data();
  std::memcpy(&point.x, p, 4);
  std::memcpy(&point.y, p + 4, 4);
  std::memcpy(&point.z, p + 8, 4);
  point.intensity = p[12];
  point.channel = p[13];
  point.return_type = p[14];
  std::memcpy(&point.timestamp_s, p + 15, 8);
  return point;
}

}  // namespace pandarcap
