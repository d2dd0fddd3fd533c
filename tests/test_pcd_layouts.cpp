// The PCD field layouts (output.pcd_fields) and axes (sensor.frame), byte by byte and then as the
// tools people use read them: PCL (pcl_convert_pcd_ascii_binary, PCL's own reader and writer)
// and Open3D (its tensor reader, which keeps every field with its type). The reference for the
// values is the same frame in the pandarcap layout, decoded here.
#include <catch2/catch.hpp>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

#include "bench/child_process.hpp"
#include "core/frames/pcd.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

Point sample_point() {
  Point p;
  p.x = 1.5f;
  p.y = -2.25f;
  p.z = 0.75f;
  p.distance_m = std::sqrt(1.5f * 1.5f + 2.25f * 2.25f + 0.75f * 0.75f);
  p.timestamp_ns = 1'795'348'800'123'456'789;
  p.azimuth_cdeg = 14'631;  // 146.31°
  p.intensity = 200;
  p.channel = 39;
  p.return_type = ReturnType::kLastStrongest;
  return p;
}

template <typename T>
T at(const std::vector<std::uint8_t>& bytes, std::size_t offset) {
  T value;
  std::memcpy(&value, bytes.data() + offset, sizeof value);
  return value;
}

std::vector<std::uint8_t> encode(const Point& p, PcdFormat format, PcdFrameContext context) {
  std::vector<std::uint8_t> bytes(pcd_point_bytes(format.layout) + 1, 0xAB);
  CHECK(encode_pcd_points(std::span(&p, 1), bytes, format, context) ==
        pcd_point_bytes(format.layout));
  CHECK(bytes.back() == 0xAB);  // nothing past the point
  return bytes;
}

}  // namespace

TEST_CASE("PCD layouts: each field at its offset, in its type and unit", "[pcd]") {
  const Point p = sample_point();
  const PcdFrameContext context{p.timestamp_ns - 2'500'000, ReturnMode::kDual};  // 2.5 ms in

  auto b = encode(p, {PcdLayout::kPcl, Axes::kHesai}, context);
  CHECK(at<float>(b, 0) == 1.5f);
  CHECK(at<float>(b, 4) == -2.25f);
  CHECK(at<float>(b, 8) == 0.75f);
  CHECK(at<float>(b, 12) == 200.0f);
  CHECK(at<std::uint16_t>(b, 16) == 39);
  CHECK(b[18] == 3);
  CHECK(at<double>(b, 19) == Approx(1'795'348'800.123456789).margin(1e-6));

  b = encode(p, {PcdLayout::kVelodyne, Axes::kHesai}, context);
  CHECK(at<float>(b, 12) == 200.0f);
  CHECK(at<std::uint16_t>(b, 16) == 39);
  CHECK(at<float>(b, 18) == Approx(0.0025).margin(1e-9));

  b = encode(p, {PcdLayout::kAutoware, Axes::kHesai}, context);
  CHECK(b[12] == 200);
  CHECK(b[13] == 6);  // nebula's IDENTICAL: both echoes were one return
  CHECK(at<std::uint16_t>(b, 14) == 39);
  CHECK(at<float>(b, 16) == Approx(146.31 * std::numbers::pi / 180).margin(1e-6));
  CHECK(at<float>(b, 20) == Approx(std::asin(0.75 / p.distance_m)).margin(1e-6));
  CHECK(at<float>(b, 24) == p.distance_m);
  CHECK(at<std::uint32_t>(b, 28) == 2'500'000);

  b = encode(p, {PcdLayout::kPandarcap, Axes::kHesai}, context);
  const PcdPoint decoded =
      decode_pcd_point(std::span<const std::uint8_t, kPcdPointBytes>(b.data(), kPcdPointBytes));
  CHECK(decoded.intensity == 200);
  CHECK(decoded.channel == 39);
  CHECK(decoded.return_type == 3);
}

TEST_CASE("PCD layouts: nebula's return-type codes for every return and mode", "[pcd]") {
  CHECK(nebula_return_type(ReturnType::kSingle, ReturnMode::kStrongest) == 3);
  CHECK(nebula_return_type(ReturnType::kSingle, ReturnMode::kLast) == 1);
  CHECK(nebula_return_type(ReturnType::kLast, ReturnMode::kDual) == 1);
  CHECK(nebula_return_type(ReturnType::kStrongest, ReturnMode::kDual) == 3);
  CHECK(nebula_return_type(ReturnType::kLastStrongest, ReturnMode::kDual) == 6);
}

TEST_CASE("sensor.frame ros: REP 103 axes, x forward at azimuth 0 and y to the left", "[pcd]") {
  // Hesai: azimuth 0 is +y, 90° (clockwise from above) is +x, so a point ahead and to the right
  // has y > 0 and x > 0. In ROS axes it is ahead (x > 0) and right (y < 0).
  const Point p = sample_point();  // x 1.5 (right), y -2.25 (behind)
  for (const PcdLayout layout :
       {PcdLayout::kPcl, PcdLayout::kPandarcap, PcdLayout::kVelodyne, PcdLayout::kAutoware}) {
    const auto b = encode(p, {layout, Axes::kRos}, {});
    INFO(to_string(layout));
    CHECK(at<float>(b, 0) == -2.25f);  // behind
    CHECK(at<float>(b, 4) == -1.5f);   // right
    CHECK(at<float>(b, 8) == 0.75f);
  }
  CHECK(parse_axes("ros") == Axes::kRos);
  CHECK(parse_axes("hesai") == Axes::kHesai);
  CHECK_FALSE(parse_axes("enu"));
}

TEST_CASE("PCD layouts: the header names the fields and anchors relative times", "[pcd]") {
  std::string header;
  append_pcd_header(header, 7, PcdLayout::kVelodyne, 1'795'348'800'123'456'789);
  CHECK(header.find("# pandarcap frame_reference_time 1795348800.123456789 "
                    "2026-11-22T12:00:00.123456789Z\n") != std::string::npos);
  CHECK(header.find("FIELDS x y z intensity ring time\nSIZE 4 4 4 4 2 4\nTYPE F F F F U F\n") !=
        std::string::npos);
  CHECK(header.find("POINTS 7\nDATA binary\n") != std::string::npos);
  for (const auto& [name, layout] :
       std::map<std::string, PcdLayout>{{"pcl", PcdLayout::kPcl},
                                        {"pandarcap", PcdLayout::kPandarcap},
                                        {"velodyne", PcdLayout::kVelodyne},
                                        {"autoware", PcdLayout::kAutoware}}) {
    CHECK(parse_pcd_layout(name) == layout);
    CHECK(to_string(layout) == name);
    // The SIZE line adds up to the point size.
    std::string h;
    append_pcd_header(h, 1, layout);
    const auto size_at = h.find("SIZE ") + 5;
    std::istringstream sizes(h.substr(size_at, h.find('\n', size_at) - size_at));
    std::size_t total = 0;
    for (std::size_t s = 0; sizes >> s;)
      total += s;
    CHECK(total == pcd_point_bytes(layout));
  }
  CHECK_FALSE(parse_pcd_layout("xyzi"));
}

namespace {

// Replays the real capture into `out` with `layout` (and `extra` options); the largest frame
// written.
fs::path replay_frame(const fs::path& capture, const fs::path& out, const std::string& layout,
                      const std::string& extra = "") {
  const auto r = test::run_command(test::pandarcapd_command() + " --replay '" + capture.string() +
                                   "' --top-speed --max-clock-offset 0 --pcd-fields " + layout +
                                   " " + extra + " --output-dir '" + out.string() + "' 2>&1");
  INFO(r.out);
  REQUIRE(r.exit_code == 0);
  fs::path largest;
  for (const fs::path& f : test::files_ending(out / "frames", ".pcd")) {
    if (largest.empty() || fs::file_size(f) > fs::file_size(largest)) largest = f;
  }
  REQUIRE_FALSE(largest.empty());
  return largest;
}

// The points the readers' values are compared at: every kStride-th, from the first. The counts
// and the types are checked for the whole file; the values at these points, and what reads
// every value (the earliest time) in the reader itself. Every point's values, parsed in the
// test under TSan, took most of this test's 47 s there.
constexpr std::size_t kStride = 997;

// PCL's reading of a file: pcl_convert_pcd_ascii_binary loads it with PCL's PCD reader and
// writes it as ASCII; the fields, how many rows, and every kStride-th row, as numbers.
struct PclView {
  std::vector<std::string> fields;
  std::size_t count = 0;
  std::vector<std::vector<double>> sampled;  // row i at sampled[i / kStride]
};
PclView read_with_pcl(const fs::path& file, const fs::path& ascii) {
  const auto r = test::run_command("pcl_convert_pcd_ascii_binary '" + file.string() + "' '" +
                                   ascii.string() + "' 0 2>&1");
  INFO(r.out);
  REQUIRE(r.exit_code == 0);
  PclView view;
  std::ifstream in(ascii);
  std::string line;
  bool data = false;
  while (std::getline(in, line)) {
    if (data) {
      if (view.count++ % kStride != 0) continue;
      std::istringstream words(line);
      std::vector<double> row;
      for (double v = 0; words >> v;)
        row.push_back(v);
      view.sampled.push_back(row);
    } else if (line.rfind("FIELDS ", 0) == 0) {
      std::istringstream words(line);
      std::string w;
      words >> w;
      while (words >> w)
        view.fields.push_back(w);
    } else {
      data = line == "DATA ascii";
    }
  }
  return view;
}

// Open3D's reading of a file (its tensor reader): each field's dtype, how many values, the
// smallest, and every kStride-th value (at values[i / kStride]).
json read_with_open3d(const fs::path& file) {
  const auto r = test::run_command(
      "/usr/bin/python3 -c '"
      "import json, sys, open3d as o3d\n"
      "pc = o3d.t.io.read_point_cloud(sys.argv[1])\n"
      "out = {k: {\"dtype\": str(pc.point[k].dtype), \"count\": len(pc.point[k]),"
      " \"min\": pc.point[k].numpy().min().item(),"
      " \"values\": pc.point[k].numpy()[::" +
      std::to_string(kStride) +
      "].tolist()} for k in pc.point}\n"
      "print(json.dumps(out))' '" +
      file.string() + "' 2>&1");
  INFO(r.out.substr(0, 2000));
  REQUIRE(r.exit_code == 0);
  return json::parse(r.out.substr(r.out.find('{')));
}

// Point i's value (i a multiple of kStride) of one field as Open3D read it.
double o3d_value(const json& o3d, const char* field, std::size_t i) {
  const json& v = o3d[field]["values"][i / kStride];
  return v.is_array() ? v[0].get<double>() : v.get<double>();
}

// What the replay of the real capture writes in the pandarcap layout: its largest frame's name
// and points. Made once for the test case's four runs (one a section).
struct Reference {
  std::string name;
  std::vector<PcdPoint> points;
};
const Reference& reference_frame(const fs::path& capture, const fs::path& out) {
  static Reference reference;
  if (reference.points.empty()) {
    const fs::path file = replay_frame(capture, out, "pandarcap");
    reference = {file.filename().string(), test::pandarcap_pcd_points(file)};
  }
  return reference;
}

}  // namespace

TEST_CASE("PCD layouts load in PCL and Open3D with the fields, types and values documented",
          "[pcd][tools][real][threads]") {
  const auto capture = test::real_capture("pandar40p_nebula_dual_600rpm_1262B.pcap");
  if (!capture) return;
  test::ScratchDir dir("pcd-layouts");
  const Reference& reference = reference_frame(*capture, dir / "pandarcap");
  const std::vector<PcdPoint>& truth = reference.points;
  REQUIRE(truth.size() > 50'000);
  const std::size_t n = truth.size();

  SECTION("pcl: float intensity, as PointXYZI wants it; ring, return_type, absolute time") {
    const fs::path file = replay_frame(*capture, dir / "pcl", "pcl");
    CHECK(file.filename() == reference.name);
    const PclView pcl = read_with_pcl(file, dir / "pcl.ascii.pcd");
    CHECK(pcl.fields ==
          std::vector<std::string>{"x", "y", "z", "intensity", "ring", "return_type", "timestamp"});
    REQUIRE(pcl.count == n);
    for (std::size_t i = 0; i < n; i += kStride) {
      const std::vector<double>& row = pcl.sampled[i / kStride];
      CHECK(row[0] == Approx(truth[i].x).margin(1e-4));
      CHECK(row[3] == truth[i].intensity);
      CHECK(row[4] == truth[i].channel);
      CHECK(row[5] == truth[i].return_type);
    }
    const json o3d = read_with_open3d(file);
    CHECK(o3d["intensity"]["dtype"] == "Float32");
    CHECK(o3d["timestamp"]["dtype"] == "Float64");
    REQUIRE(o3d["intensity"]["count"] == n);
    for (std::size_t i = 0; i < n; i += kStride) {
      CHECK(o3d_value(o3d, "intensity", i) == truth[i].intensity);
      CHECK(o3d_value(o3d, "timestamp", i) == truth[i].timestamp_s);
    }
  }

  SECTION("velodyne: PointXYZIRT, time in seconds since the frame's reference") {
    const fs::path file = replay_frame(*capture, dir / "velodyne", "velodyne");
    const double t0 = test::pcd_reference_time(file);
    const PclView pcl = read_with_pcl(file, dir / "velodyne.ascii.pcd");
    CHECK(pcl.fields == std::vector<std::string>{"x", "y", "z", "intensity", "ring", "time"});
    REQUIRE(pcl.count == n);
    const json o3d = read_with_open3d(file);
    CHECK(o3d["intensity"]["dtype"] == "Float32");
    CHECK(o3d["ring"]["dtype"] == "UInt16");
    CHECK(o3d["time"]["dtype"] == "Float32");
    REQUIRE(o3d["time"]["count"] == n);
    CHECK(o3d["time"]["min"] == 0);  // the reference is the earliest point
    for (std::size_t i = 0; i < n; i += kStride) {
      CHECK(pcl.sampled[i / kStride][4] == truth[i].channel);
      CHECK(o3d_value(o3d, "time", i) == Approx(truth[i].timestamp_s - t0).margin(1e-6));
      CHECK(o3d_value(o3d, "time", i) < 0.11);  // within one revolution
    }
  }

  SECTION("autoware: nebula's PointXYZIRCAEDT names, units and return-type codes") {
    const fs::path file = replay_frame(*capture, dir / "autoware", "autoware");
    const double t0 = test::pcd_reference_time(file);
    const PclView pcl = read_with_pcl(file, dir / "autoware.ascii.pcd");
    CHECK(pcl.fields == std::vector<std::string>{"x", "y", "z", "intensity", "return_type",
                                                 "channel", "azimuth", "elevation", "distance",
                                                 "time_stamp"});
    REQUIRE(pcl.count == n);
    const json o3d = read_with_open3d(file);
    CHECK(o3d["intensity"]["dtype"] == "UInt8");
    CHECK(o3d["return_type"]["dtype"] == "UInt8");
    CHECK(o3d["channel"]["dtype"] == "UInt16");
    CHECK(o3d["time_stamp"]["dtype"] == "UInt32");
    REQUIRE(o3d["time_stamp"]["count"] == n);
    const std::map<int, int> nebula_code{{1, 1}, {2, 3}, {3, 6}};  // last, strongest, merged
    for (std::size_t i = 0; i < n; i += kStride) {
      const PcdPoint& t = truth[i];
      const std::vector<double>& row = pcl.sampled[i / kStride];
      const double d = std::sqrt(double(t.x) * t.x + double(t.y) * t.y + double(t.z) * t.z);
      CHECK(row[3] == t.intensity);
      CHECK(row[4] == nebula_code.at(t.return_type));
      CHECK(row[5] == t.channel);
      // Hesai's azimuth: clockwise from +y, seen from above.
      const double azimuth =
          std::fmod(std::atan2(t.x, t.y) + 2 * std::numbers::pi, 2 * std::numbers::pi);
      CHECK(std::abs(std::remainder(row[6] - azimuth, 2 * std::numbers::pi)) < 2e-3);
      CHECK(row[7] == Approx(std::asin(t.z / d)).margin(1e-4));
      CHECK(row[8] == Approx(d).margin(1e-3));
      CHECK(o3d_value(o3d, "time_stamp", i) == Approx((t.timestamp_s - t0) * 1e9).margin(1000));
    }
  }

  SECTION("ros axes: the same points, x forward (the sensor's y) and y left (its -x)") {
    const fs::path file = replay_frame(*capture, dir / "ros", "pandarcap", "--frame ros");
    CHECK(file.filename() == reference.name);
    const std::vector<PcdPoint> ros = test::pandarcap_pcd_points(file);
    REQUIRE(ros.size() == n);
    for (std::size_t i = 0; i < n; i += 101) {
      CHECK(ros[i].x == truth[i].y);
      CHECK(ros[i].y == -truth[i].x);
      CHECK(ros[i].z == truth[i].z);
    }
  }
}
