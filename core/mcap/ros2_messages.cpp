#include "core/mcap/ros2_messages.hpp"

#include <array>

#include "core/frames/pcd.hpp"

namespace pandarcap::mcap {

const std::string_view kPointCloud2Schema =
    R"(std_msgs/Header header
uint32 height
uint32 width
PointField[] fields
bool is_bigendian
uint32 point_step
uint32 row_step
uint8[] data
bool is_dense

================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id

================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec

================================================================================
MSG: sensor_msgs/PointField
uint8 INT8    = 1
uint8 UINT8   = 2
uint8 INT16   = 3
uint8 UINT16  = 4
uint8 INT32   = 5
uint8 UINT32  = 6
uint8 FLOAT32 = 7
uint8 FLOAT64 = 8
string name
uint32 offset
uint8  datatype
uint32 count
)";

const std::string_view kPandarPacketSchema =
    R"(builtin_interfaces/Time stamp
uint8[] data
uint32 size

================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
)";

namespace {

// sensor_msgs/PointField datatypes.
constexpr std::uint8_t kUint8 = 2, kUint16 = 4, kUint32 = 6, kFloat32 = 7, kFloat64 = 8;

// PointField's datatype for a PCD field (sensor_msgs/PointField's constants).
std::uint8_t datatype(const PcdField& f) noexcept {
  if (f.type == 'F') return f.size == 8 ? kFloat64 : kFloat32;
  switch (f.size) {
    case 1:
      return kUint8;
    case 2:
      return kUint16;
    default:
      return kUint32;
  }
}

constexpr std::size_t kEncapsulation = 4;

// CDR aligns to the field's size, counted from after the encapsulation header.
std::size_t aligned(std::size_t at, std::size_t size) noexcept {
  const std::size_t body = at - kEncapsulation;
  return at + (size - body % size) % size;
}

// Writes the padding that aligns the next `size`-byte field; `start` is the message's first
// byte in the writer.
void align(ByteWriter& w, std::size_t start, std::size_t size) {
  const std::size_t at = w.size() - start;
  for (std::size_t i = at; i < aligned(at, size); ++i)
    w.u8(0);
}

void cdr_string(ByteWriter& w, std::string_view s) {
  w.u32(static_cast<std::uint32_t>(s.size() + 1));  // CDR strings count their NUL
  w.bytes(s);
  w.u8(0);
}

void encapsulation(ByteWriter& w) {
  w.u8(0);
  w.u8(1);  // CDR_LE
  w.u8(0);
  w.u8(0);
}

}  // namespace

RosTime ros_time(std::int64_t unix_ns) noexcept {
  std::int64_t sec = unix_ns / 1'000'000'000;
  std::int64_t ns = unix_ns % 1'000'000'000;
  if (ns < 0) {
    ns += 1'000'000'000;
    --sec;
  }
  return RosTime{static_cast<std::int32_t>(sec), static_cast<std::uint32_t>(ns)};
}

std::size_t pointcloud2_prefix_bytes(std::size_t frame_id_bytes, PcdLayout layout) noexcept {
  std::size_t at = kEncapsulation + 8;  // stamp
  at += 4 + frame_id_bytes + 1;         // frame_id
  at = aligned(at, 4) + 4 + 4 + 4;      // height, width, fields' count
  for (const PcdField& f : pcd_fields(layout)) {
    at = aligned(at, 4) + 4 + f.name.size() + 1;  // name
    at = aligned(at, 4) + 4 + 1;                  // offset, datatype
    at = aligned(at, 4) + 4;                      // count
  }
  at += 1;                          // is_bigendian
  at = aligned(at, 4) + 4 + 4 + 4;  // point_step, row_step, data's length
  return at;
}

void write_pointcloud2_prefix(ByteWriter& w, RosTime stamp, std::string_view frame_id,
                              std::uint32_t points, PcdLayout layout) {
  const std::span<const PcdField> fields = pcd_fields(layout);
  const auto step = static_cast<std::uint32_t>(pcd_point_bytes(layout));
  const std::size_t start = w.size();
  encapsulation(w);
  w.u32(static_cast<std::uint32_t>(stamp.sec));
  w.u32(stamp.nanosec);
  cdr_string(w, frame_id);
  align(w, start, 4);
  w.u32(1);       // height: an unordered cloud
  w.u32(points);  // width
  w.u32(static_cast<std::uint32_t>(fields.size()));
  for (const PcdField& f : fields) {
    align(w, start, 4);
    cdr_string(w, f.name);
    align(w, start, 4);
    w.u32(f.offset);
    w.u8(datatype(f));
    align(w, start, 4);
    w.u32(1);  // count
  }
  w.u8(0);  // is_bigendian
  align(w, start, 4);
  w.u32(step);           // point_step
  w.u32(step * points);  // row_step
  w.u32(step * points);  // data: length, then the bytes
}

void write_pointcloud2_suffix(ByteWriter& w) {
  w.u8(1);  // is_dense: the decoder keeps only returns with a range, never NaN points
}

std::size_t pandar_packet_bytes(std::size_t payload_bytes) noexcept {
  const std::size_t at = kEncapsulation + 8 + 4 + payload_bytes;
  return aligned(at, 4) + 4;
}

void write_pandar_packet(ByteWriter& w, RosTime stamp, std::span<const std::uint8_t> payload) {
  const std::size_t start = w.size();
  encapsulation(w);
  w.u32(static_cast<std::uint32_t>(stamp.sec));
  w.u32(stamp.nanosec);
  w.u32(static_cast<std::uint32_t>(payload.size()));
  w.bytes(payload);
  align(w, start, 4);
  w.u32(static_cast<std::uint32_t>(payload.size()));
}

std::optional<PandarPacketView> parse_pandar_packet(std::span<const std::uint8_t> cdr) noexcept {
  // Encapsulation: 00 00 plain CDR big-endian, 00 01 little-endian; then two option bytes.
  if (cdr.size() < kEncapsulation || cdr[0] != 0 || cdr[1] > 1) return std::nullopt;
  const bool little = cdr[1] == 1;
  std::size_t at = kEncapsulation;
  const auto u32 = [&](std::uint32_t& v) {
    at = aligned(at, 4);
    if (cdr.size() < at || cdr.size() - at < 4) return false;
    const std::uint8_t* p = cdr.data() + at;
    v = little ? (std::uint32_t{p[0]} | std::uint32_t{p[1]} << 8 | std::uint32_t{p[2]} << 16 |
                  std::uint32_t{p[3]} << 24)
               : (std::uint32_t{p[3]} | std::uint32_t{p[2]} << 8 | std::uint32_t{p[1]} << 16 |
                  std::uint32_t{p[0]} << 24);
    at += 4;
    return true;
  };
  std::uint32_t sec = 0, nanosec = 0, length = 0, size = 0;
  if (!u32(sec) || !u32(nanosec) || !u32(length)) return std::nullopt;
  if (cdr.size() - at < length) return std::nullopt;
  const std::span<const std::uint8_t> data = cdr.subspan(at, length);
  at += length;
  if (!u32(size) || size > length) return std::nullopt;
  return PandarPacketView{RosTime{static_cast<std::int32_t>(sec), nanosec}, data.first(size)};
}

}  // namespace pandarcap::mcap
