// Frames as PCD v0.7 binary files, the Point Cloud Library's format (pcl_viewer, CloudCompare,
// Open3D and ROS tools read it), in one of four field layouts (output.pcd_fields) so each
// family of tools finds the fields it looks for, with the names, types and units it expects.
// All little-endian, packed with no padding; x y z F4 metres in every layout, in the axes of
// output frame convention (sensor.frame).
//
//   pcl (the default, 27 B): what PCL's PointXYZI readers and every viewer colouring by
//       intensity want, losing nothing:
//         x y z F4 | intensity F4 (the reflectivity byte, 0..255) | ring U2 (channel 0..39) |
//         return_type U1 (codes below) | timestamp F8 (s since the Unix epoch)
//   pandarcap (23 B): the compact layout, also the MCAP PointCloud2 messages' layout:
//         x y z F4 | intensity U1 | channel U1 | return_type U1 | timestamp F8 (epoch s)
//   velodyne (22 B): velodyne_pointcloud's PointXYZIRT, as LIO-SAM and similar tools read it:
//         x y z F4 | intensity F4 | ring U2 (channel) | time F4 (s since the frame's reference)
//   autoware (32 B): nebula's PointXYZIRCAEDT, names and codes as nebula publishes them:
//         x y z F4 | intensity U1 | return_type U1 (nebula's codes) | channel U2 |
//         azimuth F4 (rad) | elevation F4 (rad) | distance F4 (m) |
//         time_stamp U4 (ns since the frame's reference)
//
// Return types. pandarcap's codes (pcl and pandarcap layouts): 0 single return (the frame's
// return mode says strongest or last), 1 last, 2 strongest, 3 last and strongest merged (both
// echoes of a dual-return firing were the same return: one point). nebula's (autoware layout):
// single strongest 3 (STRONGEST), single last 1 (LAST), dual last 1, dual strongest 3, merged 6
// (IDENTICAL).
//
// The frame's reference time is its earliest point's time. Every header written for a frame
// states it in a comment line that PCL and Open3D skip:
//   # pandarcap frame_reference_time 1795348800.123456789 2026-11-22T12:00:00.123456789Z
// so the relative times of the velodyne and autoware layouts keep an absolute anchor.
// The header keys come in the order PCL writes and expects them; an unordered cloud has
// WIDTH = POINTS and HEIGHT = 1. The points follow as "DATA binary" (packed rows, encoded here)
// or as "DATA binary_compressed" (LZF, output.pcd_compression; core/frames/pcd_compressed.hpp).
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>

#include "core/frames/point.hpp"
#include "core/sensors/packet.hpp"

namespace pandarcap {

enum class PcdLayout : std::uint8_t { kPcl, kPandarcap, kVelodyne, kAutoware };
inline constexpr std::string_view kPcdLayoutNames = "pcl, pandarcap, velodyne, autoware";
std::string_view to_string(PcdLayout layout) noexcept;  // "pcl", "pandarcap", ...
std::optional<PcdLayout> parse_pcd_layout(std::string_view name) noexcept;

// The axes x y z are written in. hesai: the sensor's own (y towards azimuth 0, x towards 90°,
// clockwise seen from above, z up). ros: REP 103 (x forward = the sensor's azimuth 0, y left,
// z up), i.e. x_ros = y_hesai, y_ros = -x_hesai.
enum class Axes : std::uint8_t { kHesai, kRos };
std::string_view to_string(Axes axes) noexcept;  // "hesai", "ros"
std::optional<Axes> parse_axes(std::string_view name) noexcept;

struct PcdFormat {
  PcdLayout layout = PcdLayout::kPcl;
  Axes axes = Axes::kHesai;
};

// What a frame's points are encoded against: the reference of the relative times and the
// return mode single-return points were taken in.
struct PcdFrameContext {
  std::int64_t reference_ns = 0;
  ReturnMode return_mode = ReturnMode::kDual;
};

inline constexpr std::size_t kPcdPointBytes = 3 * 4 + 3 * 1 + 8;  // 23: the pandarcap layout
inline constexpr std::size_t kMaxPcdPointBytes = 32;              // the autoware layout
std::size_t pcd_point_bytes(PcdLayout layout) noexcept;

// A field of a layout, where it sits in a point: what a PointCloud2's PointField says. A layout's
// fields come in order, and their sizes add up to pcd_point_bytes.
struct PcdField {
  std::string_view name;
  std::uint32_t offset = 0;
  std::uint8_t size = 0;  // bytes: 1, 2, 4 or 8
  char type = 'F';        // 'F' float, 'U' unsigned, as the header's TYPE line
};
std::span<const PcdField> pcd_fields(PcdLayout layout) noexcept;

// How the points follow the header: its DATA line.
enum class PcdData : std::uint8_t { kBinary, kBinaryCompressed };

// The pandarcap layout's ASCII header for `points` points, ending with "DATA binary\n".
std::string pcd_header(std::size_t points);
// A layout's header appended to `out` (no allocation once `out` has room), with the frame's
// reference time in a comment when `reference_ns` is given.
void append_pcd_header(std::string& out, std::size_t points,
                       PcdLayout layout = PcdLayout::kPandarcap,
                       std::optional<std::int64_t> reference_ns = std::nullopt,
                       PcdData data = PcdData::kBinary);

// Pads a header made by append_pcd_header to exactly `size` bytes with a comment line of spaces
// (PCL and Open3D skip comment lines) just before VERSION, so the points start at byte `size`:
// a page boundary, which lets them be written from the arena past the page cache (O_DIRECT).
// False, with `header` untouched, when it is already too long for that.
bool pad_pcd_header(std::string& header, std::size_t size);

// Encodes points into `out` (which must hold points.size() * pcd_point_bytes(layout) bytes) and
// returns the bytes written. No allocation. The default is the pandarcap layout in Hesai axes.
std::size_t encode_pcd_points(std::span<const Point> points, std::span<std::uint8_t> out,
                              PcdFormat format = {PcdLayout::kPandarcap, Axes::kHesai},
                              PcdFrameContext frame = {}) noexcept;

// Moves the relative times of encoded rows (the velodyne and autoware layouts; nothing for the
// others, whose times are absolute) from one reference to another `shift_ns` earlier: each time
// grows by shift_ns. A frame arena encodes against its first point's time and rebases once at
// the end if an earlier point came later (a reordered packet). The autoware layout's U4 times
// are kept modulo 2^32 while encoding, so a point before the first one comes out right.
void rebase_pcd_times(std::span<std::uint8_t> rows, PcdLayout layout,
                      std::int64_t shift_ns) noexcept;

// nebula's return-type code for a point (autoware layout).
std::uint8_t nebula_return_type(ReturnType type, ReturnMode mode) noexcept;

// The fields of one point in the pandarcap layout, for tests and tools reading files back.
struct PcdPoint {
  float x = 0, y = 0, z = 0;
  std::uint8_t intensity = 0, channel = 0, return_type = 0;
  double timestamp_s = 0;
};
PcdPoint decode_pcd_point(std::span<const std::uint8_t, kPcdPointBytes> bytes) noexcept;

}  // namespace pandarcap
