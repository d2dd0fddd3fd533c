// The ROS 2 messages pandarcap's MCAP files carry, serialised as CDR (the encoding ROS 2 and
// rosbag2 use, and Foxglove reads): a 4-byte encapsulation header (00 01 00 00: plain CDR,
// little-endian), then each field aligned to its own size counted from after that header.
//
//   sensor_msgs/msg/PointCloud2   one per frame. Its points are the PCD files' bytes exactly, in
//                                 the same layout (core/frames/pcd.hpp: output.pcd_fields; the
//                                 fields name each of the layout's), so both outputs agree point
//                                 for point; header.stamp is the frame's first firing time, the
//                                 reference of the relative-time layouts.
//   pandar_msgs/msg/PandarPacket  one per datagram (optional): receive time, payload, size, as
//                                 Hesai's ROS 2 driver defines it.
// Each schema text is the message definition with its dependencies appended, as rosbag2 writes
// "ros2msg" schemas.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string_view>

#include "core/frames/pcd.hpp"
#include "core/mcap/mcap_records.hpp"

namespace pandarcap::mcap {

extern const std::string_view kPointCloud2Schema;
extern const std::string_view kPandarPacketSchema;
inline constexpr std::string_view kPointCloud2Name = "sensor_msgs/msg/PointCloud2";
inline constexpr std::string_view kPandarPacketName = "pandar_msgs/msg/PandarPacket";

// A ROS time: whole seconds since the Unix epoch and nanoseconds (floor division, so times before
// 1970 keep 0 <= nanosec < 1e9).
struct RosTime {
  std::int32_t sec = 0;
  std::uint32_t nanosec = 0;
};
RosTime ros_time(std::int64_t unix_ns) noexcept;

// Bytes of a PointCloud2 message before its point data (encapsulation header included), for a
// frame id of `frame_id_bytes` characters and points in `layout`.
std::size_t pointcloud2_prefix_bytes(std::size_t frame_id_bytes,
                                     PcdLayout layout = PcdLayout::kPandarcap) noexcept;
// The message's bytes after the point data (is_dense).
inline constexpr std::size_t kPointCloud2SuffixBytes = 1;

// Writes a PointCloud2 message up to (and including) the data length: the caller appends
// `points` * pcd_point_bytes(layout) bytes of PCD point data and then
// write_pointcloud2_suffix().
void write_pointcloud2_prefix(ByteWriter& w, RosTime stamp, std::string_view frame_id,
                              std::uint32_t points, PcdLayout layout = PcdLayout::kPandarcap);
void write_pointcloud2_suffix(ByteWriter& w);

// The bytes of a PandarPacket message for a payload of `payload_bytes`.
std::size_t pandar_packet_bytes(std::size_t payload_bytes) noexcept;
void write_pandar_packet(ByteWriter& w, RosTime stamp, std::span<const std::uint8_t> payload);

// A PandarPacket message read back from untrusted CDR bytes (little- or big-endian
// encapsulation). `data` is the packet: the first `size` bytes of the message's data array (Hesai's
// driver may send a larger array than the datagram; pandarcap writes size == the array's length).
// Nothing when the bytes do not hold a whole message or `size` exceeds the array.
struct PandarPacketView {
  RosTime stamp;
  std::span<const std::uint8_t> data;
};
std::optional<PandarPacketView> parse_pandar_packet(std::span<const std::uint8_t> cdr) noexcept;

}  // namespace pandarcap::mcap
