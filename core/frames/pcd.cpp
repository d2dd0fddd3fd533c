#include "core/frames/pcd.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cassert>
#include <cmath>
#include <cstring>
#include <numbers>

#include "core/utc_time.hpp"

namespace pandarcap {

static_assert(std::endian::native == std::endian::little,
              "PCD binary data is written in host order; readers assume little-endian");

namespace {

struct LayoutSpec {
  std::string_view name;
  std::size_t point_bytes;
  std::string_view fields, sizes, types, counts;
};

// Indexed by PcdLayout.
constexpr LayoutSpec kLayouts[] = {
    {"pcl", 27, "x y z intensity ring return_type timestamp", "4 4 4 4 2 1 8", "F F F F U U F",
     "1 1 1 1 1 1 1"},
    {"pandarcap", 23, "x y z intensity channel return_type timestamp", "4 4 4 1 1 1 8",
     "F F F U U U F", "1 1 1 1 1 1 1"},
    {"velodyne", 22, "x y z intensity ring time", "4 4 4 4 2 4", "F F F F U F", "1 1 1 1 1 1"},
    {"autoware", 32, "x y z intensity return_type channel azimuth elevation distance time_stamp",
     "4 4 4 1 1 2 4 4 4 4", "F F F U U U F F F U", "1 1 1 1 1 1 1 1 1 1"},
};

// The FIELDS, SIZE and TYPE lines as one PcdField per field (every size is one digit: 1, 2, 4
// or 8).
struct FieldList {
  std::array<PcdField, 10> fields{};
  std::size_t count = 0;
};
constexpr FieldList parse_fields(const LayoutSpec& s) {
  FieldList list;
  std::size_t name = 0, type = 0;
  std::uint32_t offset = 0;
  for (const char size : s.sizes) {
    if (size == ' ') continue;
    std::size_t end = s.fields.find(' ', name);
    if (end == std::string_view::npos) end = s.fields.size();
    PcdField& f = list.fields[list.count++];
    f.name = s.fields.substr(name, end - name);
    f.offset = offset;
    f.size = static_cast<std::uint8_t>(size - '0');
    f.type = s.types[type];
    offset += f.size;
    name = end + 1;
    type += 2;
  }
  return list;
}
constexpr FieldList kFieldLists[] = {parse_fields(kLayouts[0]), parse_fields(kLayouts[1]),
                                     parse_fields(kLayouts[2]), parse_fields(kLayouts[3])};
constexpr bool sizes_add_up() {
  for (std::size_t i = 0; i < std::size(kLayouts); ++i) {
    const FieldList& f = kFieldLists[i];
    const PcdField& last = f.fields[f.count - 1];
    if (last.offset + last.size != kLayouts[i].point_bytes) return false;
  }
  return std::size(kFieldLists) == std::size(kLayouts);
}
static_assert(sizes_add_up(), "each layout's SIZE line adds up to its point size");

const LayoutSpec& spec(PcdLayout layout) noexcept {
  return kLayouts[static_cast<std::size_t>(layout)];
}

// Seconds since the epoch as a double, split before converting so it keeps all it can
// (~0.24 µs at today's dates).
// Where the compiler fuses a multiply and an add (__FP_FAST_FMA: ARM64; GCC fuses by default),
// it is written fused, so the SIMD encoder (core/decode/pcd_simd_encoder.hpp) can round alike.
double epoch_seconds(std::int64_t ns) noexcept {
  const auto seconds = static_cast<double>(ns / 1'000'000'000);
  const auto fraction = static_cast<double>(ns % 1'000'000'000);
#if defined(__FP_FAST_FMA)
  return std::fma(fraction, 1e-9, seconds);
#else
  return seconds + fraction * 1e-9;
#endif
}

template <typename T>
std::uint8_t* put(std::uint8_t* p, T value) noexcept {
  std::memcpy(p, &value, sizeof value);
  return p + sizeof value;
}

}  // namespace

std::string_view to_string(PcdLayout layout) noexcept {
  return spec(layout).name;
}

std::optional<PcdLayout> parse_pcd_layout(std::string_view name) noexcept {
  for (std::size_t i = 0; i < std::size(kLayouts); ++i) {
    if (kLayouts[i].name == name) return static_cast<PcdLayout>(i);
  }
  return std::nullopt;
}

std::string_view to_string(Axes axes) noexcept {
  return axes == Axes::kRos ? "ros" : "hesai";
}

std::optional<Axes> parse_axes(std::string_view name) noexcept {
  if (name == "hesai") return Axes::kHesai;
  if (name == "ros") return Axes::kRos;
  return std::nullopt;
}

std::size_t pcd_point_bytes(PcdLayout layout) noexcept {
  return spec(layout).point_bytes;
}

std::span<const PcdField> pcd_fields(PcdLayout layout) noexcept {
  const FieldList& f = kFieldLists[static_cast<std::size_t>(layout)];
  return std::span(f.fields).first(f.count);
}

void rebase_pcd_times(std::span<std::uint8_t> rows, PcdLayout layout,
                      std::int64_t shift_ns) noexcept {
  if (layout != PcdLayout::kVelodyne && layout != PcdLayout::kAutoware) return;
  // The relative time is each of these layouts' last field: velodyne's `time` (F4 seconds),
  // autoware's `time_stamp` (U4 ns, kept modulo 2^32 as encoded).
  const std::size_t step = pcd_point_bytes(layout);
  const std::size_t time_at = pcd_fields(layout).back().offset;
  const double shift_s = static_cast<double>(shift_ns) * 1e-9;
  const auto shift_u4 = static_cast<std::uint32_t>(shift_ns);
  for (std::size_t at = time_at; at + 4 <= rows.size(); at += step) {
    std::uint8_t* field = rows.data() + at;
    if (layout == PcdLayout::kVelodyne) {
      float t;
      std::memcpy(&t, field, 4);
      put(field, static_cast<float>(t + shift_s));
    } else {
      std::uint32_t t;
      std::memcpy(&t, field, 4);
      put(field, static_cast<std::uint32_t>(t + shift_u4));
    }
  }
}

std::string pcd_header(std::size_t points) {
  std::string out;
  append_pcd_header(out, points);
  return out;
}

void append_pcd_header(std::string& out, std::size_t points, PcdLayout layout,
                       std::optional<std::int64_t> reference_ns, PcdData data) {
  const LayoutSpec& s = spec(layout);
  out += "# .PCD v0.7 - Point Cloud Data file format\n";
  if (reference_ns) {
    const UnixTime t = split_unix_ns(*reference_ns);
    fmt::format_to(std::back_inserter(out), "# pandarcap frame_reference_time {}.{:09} ", t.seconds,
                   t.nanoseconds);
    append_rfc3339(out, *reference_ns, 9);
    out += '\n';
  }
  fmt::format_to(std::back_inserter(out),
                 "VERSION 0.7\n"
                 "FIELDS {}\n"
                 "SIZE {}\n"
                 "TYPE {}\n"
                 "COUNT {}\n"
                 "WIDTH {}\n"
                 "HEIGHT 1\n"
                 "VIEWPOINT 0 0 0 1 0 0 0\n"
                 "POINTS {}\n"
                 "DATA {}\n",
                 s.fields, s.sizes, s.types, s.counts, points, points,
                 data == PcdData::kBinaryCompressed ? "binary_compressed" : "binary");
}

bool pad_pcd_header(std::string& header, std::size_t size) {
  const std::size_t at = header.find("\nVERSION ");
  // The padding line is "#", spaces, "\n": at least two bytes.
  if (at == std::string::npos || header.size() + 2 > size) return false;
  const std::size_t spaces = size - header.size() - 2;
  header.insert(at + 1, spaces + 2, ' ');
  header[at + 1] = '#';
  header[at + 2 + spaces] = '\n';
  return true;
}

std::uint8_t nebula_return_type(ReturnType type, ReturnMode mode) noexcept {
  // nebula's ReturnType: UNKNOWN 0, LAST 1, FIRST 2, STRONGEST 3, ..., IDENTICAL 6.
  switch (type) {
    case ReturnType::kSingle:
      return mode == ReturnMode::kLast ? 1 : 3;
    case ReturnType::kLast:
      return 1;
    case ReturnType::kStrongest:
      return 3;
    case ReturnType::kLastStrongest:
      return 6;
  }
  return 0;
}

namespace {

// One layout's rows, the layout and axes fixed at compile time so the loop has no branch on them.
template <PcdLayout Layout, bool Ros>
std::uint8_t* encode_rows(std::span<const Point> points, std::uint8_t* p,
                          PcdFrameContext frame) noexcept {
  for (const Point& point : points) {
    p = put(p, Ros ? point.y : point.x);
    p = put(p, Ros ? -point.x : point.y);
    p = put(p, point.z);
    if constexpr (Layout == PcdLayout::kPcl) {
      p = put(p, static_cast<float>(point.intensity));
      p = put(p, static_cast<std::uint16_t>(point.channel));
      p = put(p, static_cast<std::uint8_t>(point.return_type));
      p = put(p, epoch_seconds(point.timestamp_ns));
    } else if constexpr (Layout == PcdLayout::kPandarcap) {
      p = put(p, point.intensity);
      p = put(p, point.channel);
      p = put(p, static_cast<std::uint8_t>(point.return_type));
      p = put(p, epoch_seconds(point.timestamp_ns));
    } else if constexpr (Layout == PcdLayout::kVelodyne) {
      p = put(p, static_cast<float>(point.intensity));
      p = put(p, static_cast<std::uint16_t>(point.channel));
      p = put(p, static_cast<float>(static_cast<double>(point.timestamp_ns - frame.reference_ns) *
                                    1e-9));
    } else {
      p = put(p, point.intensity);
      p = put(p, nebula_return_type(point.return_type, frame.return_mode));
      p = put(p, static_cast<std::uint16_t>(point.channel));
      p = put(p, static_cast<float>(point.azimuth_cdeg * (std::numbers::pi / 18000.0)));
      const float horizontal = std::hypot(point.x, point.y);
      p = put(p, std::atan2(point.z, horizontal));
      p = put(p, point.distance_m);
      // Before the reference only while a frame arena is filled (see rebase_pcd_times).
      const std::int64_t since = point.timestamp_ns - frame.reference_ns;
      p = put(p, since < 0 ? static_cast<std::uint32_t>(since)
                           : static_cast<std::uint32_t>(std::min<std::int64_t>(since, UINT32_MAX)));
    }
  }
  return p;
}

template <PcdLayout Layout>
std::uint8_t* encode_rows(std::span<const Point> points, std::uint8_t* p, Axes axes,
                          PcdFrameContext frame) noexcept {
  return axes == Axes::kRos ? encode_rows<Layout, true>(points, p, frame)
                            : encode_rows<Layout, false>(points, p, frame);
}

}  // namespace

std::size_t encode_pcd_points(std::span<const Point> points, std::span<std::uint8_t> out,
                              PcdFormat format, PcdFrameContext frame) noexcept {
  assert(out.size() >= points.size() * pcd_point_bytes(format.layout));
  std::uint8_t* p = out.data();
  switch (format.layout) {
    case PcdLayout::kPcl:
      p = encode_rows<PcdLayout::kPcl>(points, p, format.axes, frame);
      break;
    case PcdLayout::kPandarcap:
      p = encode_rows<PcdLayout::kPandarcap>(points, p, format.axes, frame);
      break;
    case PcdLayout::kVelodyne:
      p = encode_rows<PcdLayout::kVelodyne>(points, p, format.axes, frame);
      break;
    case PcdLayout::kAutoware:
      p = encode_rows<PcdLayout::kAutoware>(points, p, format.axes, frame);
      break;
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
