// PCD DATA binary_compressed (output.pcd_compression = "lzf"): decoded here independently of the
// encoder (the header's SIZE and POINTS lines, liblzf's lzf_decompress, the columns back into
// rows) to exactly the bytes of DATA binary, in every layout; read by PCL and Open3D to the same
// values as the binary file; written by the daemon, live and in a replay of the real capture,
// where it must take at most 0.7 of the uncompressed size.
#include <lzf.h>

#include <array>
#include <catch2/catch.hpp>
#include <cstring>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "bench/child_process.hpp"
#include "core/decode/calibration.hpp"
#include "core/decode/stream_decoder.hpp"
#include "core/frames/frame_collector.hpp"
#include "core/frames/pcd.hpp"
#include "core/frames/pcd_compressed.hpp"
#include "core/sim/synthetic_sensor.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
using namespace std::chrono_literals;
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

constexpr std::array kLayouts = {PcdLayout::kPcl, PcdLayout::kPandarcap, PcdLayout::kVelodyne,
                                 PcdLayout::kAutoware};

// A PCD file's text up to and including its DATA line, and what follows it.
struct PcdFile {
  std::string header;
  std::string data;
};
PcdFile split_pcd(const std::string& bytes) {
  const auto at = bytes.find("\nDATA ");
  REQUIRE(at != std::string::npos);
  const auto end = bytes.find('\n', at + 1);
  REQUIRE(end != std::string::npos);
  return {bytes.substr(0, end + 1), bytes.substr(end + 1)};
}

// The numbers on a header line ("SIZE 4 4 4 1 1 1 8", "POINTS 7").
std::vector<std::size_t> header_numbers(const std::string& header, const std::string& key) {
  const auto at = header.find("\n" + key + " ");
  REQUIRE(at != std::string::npos);
  const auto begin = at + key.size() + 2;
  std::istringstream words(header.substr(begin, header.find('\n', begin) - begin));
  std::vector<std::size_t> numbers;
  for (std::size_t n = 0; words >> n;)
    numbers.push_back(n);
  return numbers;
}

// A binary_compressed file's points as the packed rows DATA binary would hold, decoded as PCL's
// reader does: compressed and uncompressed sizes (U4 each), LZF, then field-major columns.
std::string decode_compressed(const std::string& bytes) {
  const PcdFile file = split_pcd(bytes);
  REQUIRE(file.header.ends_with("\nDATA binary_compressed\n"));
  const std::vector<std::size_t> sizes = header_numbers(file.header, "SIZE");
  const std::size_t points = header_numbers(file.header, "POINTS").at(0);
  std::size_t step = 0;
  for (const std::size_t s : sizes)
    step += s;
  REQUIRE(file.data.size() >= 8);
  std::uint32_t compressed = 0, uncompressed = 0;
  std::memcpy(&compressed, file.data.data(), 4);
  std::memcpy(&uncompressed, file.data.data() + 4, 4);
  REQUIRE(uncompressed == points * step);
  REQUIRE(file.data.size() == 8 + compressed);  // nothing after the LZF data
  std::string columns(uncompressed, '\0');
  if (points > 0) {
    REQUIRE(lzf_decompress(file.data.data() + 8, compressed, columns.data(), uncompressed) ==
            uncompressed);
  }
  std::string rows(uncompressed, '\0');
  std::size_t column = 0, offset = 0;
  for (const std::size_t size : sizes) {
    for (std::size_t i = 0; i < points; ++i)
      std::memcpy(&rows[i * step + offset], &columns[column + i * size], size);
    column += points * size;
    offset += size;
  }
  return rows;
}

void write_pcd_bytes(const fs::path& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary);
  out << bytes;
  REQUIRE(out.good());
}

std::string as_text(std::span<const std::uint8_t> bytes) {
  return {reinterpret_cast<const char*>(bytes.data()), bytes.size()};
}

// A frame's whole PCD file, binary or binary_compressed.
std::string binary_pcd(std::span<const Point> points, PcdFormat format, PcdFrameContext context) {
  std::string out;
  append_pcd_header(out, points.size(), format.layout, context.reference_ns);
  std::vector<std::uint8_t> rows(points.size() * pcd_point_bytes(format.layout));
  out += as_text({rows.data(), encode_pcd_points(points, rows, format, context)});
  return out;
}
std::string compressed_pcd(PcdCompressor& compressor, std::span<const Point> points,
                           PcdFormat format, PcdFrameContext context) {
  std::string out;
  append_pcd_header(out, points.size(), format.layout, context.reference_ns,
                    PcdData::kBinaryCompressed);
  return out + as_text(compressor.compress(points, format, context));
}

// One complete revolution of the simulated sensor, decoded.
std::vector<Point> simulated_revolution() {
  std::vector<Point> points;
  FrameCollector collector(4, kDefaultFrameCapacityPoints, [&](const Frame& frame) {
    if (!frame.info.partial && points.empty())
      points.assign(frame.used().begin(), frame.used().end());
  });
  StreamDecoder decoder(Calibration::nominal(), {}, collector);
  SyntheticSensor sensor({});
  std::array<std::uint8_t, kMaxPacketBytes> packet{};
  while (points.empty())
    decoder.process({packet.data(), sensor.next(packet)});
  return points;
}

// Points of random bytes: what LZF cannot shrink.
std::vector<Point> noise(std::size_t n) {
  std::mt19937 random(7);
  std::vector<Point> points(n);
  for (Point& p : points) {
    p.x = std::uniform_real_distribution<float>(-100, 100)(random);
    p.y = std::uniform_real_distribution<float>(-100, 100)(random);
    p.z = std::uniform_real_distribution<float>(-100, 100)(random);
    p.distance_m = std::uniform_real_distribution<float>(0, 200)(random);
    p.timestamp_ns = std::uniform_int_distribution<std::int64_t>(0, 1'000'000'000'000)(random);
    p.azimuth_cdeg = static_cast<std::uint16_t>(random() % 36000);
    p.intensity = static_cast<std::uint8_t>(random());
    p.channel = static_cast<std::uint8_t>(random() % 40);
    p.return_type = static_cast<ReturnType>(random() % 4);
  }
  return points;
}

// The largest complete frame of the real dual-return capture, decoded with its calibration.
struct RealFrame {
  std::vector<Point> points;
  PcdFrameContext context;
};
std::optional<RealFrame> real_frame() {
  const auto capture = test::real_capture("pandar40p_nebula_dual_600rpm_1262B.pcap");
  const auto calibration = test::real_capture("nebula_Pandar40P_calibration.csv");
  if (!capture || !calibration) return std::nullopt;
  RealFrame largest;
  FrameCollector collector(3, kDefaultFrameCapacityPoints, [&](const Frame& frame) {
    if (!frame.info.partial && frame.size > largest.points.size()) {
      largest.points.assign(frame.used().begin(), frame.used().end());
      largest.context = {frame.info.start_ns, frame.info.return_mode};
    }
  });
  test::decode_capture(*capture, *calibration, collector);
  REQUIRE(largest.points.size() > 50'000);
  return largest;
}

}  // namespace

TEST_CASE("PCD binary_compressed: every layout decodes to the binary file's bytes exactly",
          "[pcd]") {
  const std::vector<Point> revolution = simulated_revolution();
  REQUIRE(revolution.size() > 4097);
  const std::vector<Point> random_points = noise(5000);
  const std::map<std::string, std::span<const Point>> frames{
      {"a revolution", revolution},
      {"a chunk and one point", std::span(revolution).first(4097)},
      {"one point", std::span(revolution).first(1)},
      {"random bytes", random_points},
  };
  const PcdFrameContext context{revolution.front().timestamp_ns, ReturnMode::kDual};
  for (const PcdLayout layout : kLayouts) {
    for (const Axes axes : {Axes::kHesai, Axes::kRos}) {
      PcdCompressor compressor;
      compressor.reserve(revolution.size(), layout);
      const std::uint8_t* buffer = compressor.compress({}, {layout, axes}, context).data();
      for (const auto& [name, points] : frames) {
        INFO(to_string(layout) << " " << to_string(axes) << ": " << name);
        const PcdFormat format{layout, axes};
        const std::string compressed = compressed_pcd(compressor, points, format, context);
        const PcdFile binary = split_pcd(binary_pcd(points, format, context));
        CHECK(decode_compressed(compressed) == binary.data);
        // The same header but for its DATA line.
        CHECK(split_pcd(compressed).header ==
              binary.header.substr(0, binary.header.size() - 7) + "binary_compressed\n");
        // Within the reserve the buffers stay where they were: compressing allocated nothing.
        CHECK(compressor.compress(points, format, context).data() == buffer);
        if (name == "a revolution") CHECK(compressed.size() < binary.data.size() * 7 / 10);
        if (name == "random bytes") {
          // Random floats do not shrink; LZF still holds them, within its bound.
          CHECK(compressed.size() - split_pcd(compressed).header.size() <=
                pcd_compressed_bound(points.size(), layout));
        }
      }
    }
  }
}

TEST_CASE("PCD binary_compressed: no points is two zero sizes and no data, as PCL writes it",
          "[pcd]") {
  for (const PcdLayout layout : kLayouts) {
    PcdCompressor compressor;
    const std::string file = compressed_pcd(compressor, {}, {layout, Axes::kHesai}, {});
    CHECK(split_pcd(file).data == std::string(8, '\0'));
    CHECK(file.find("\nPOINTS 0\nDATA binary_compressed\n") != std::string::npos);
    CHECK(decode_compressed(file).empty());
  }
}

TEST_CASE("PCD binary_compressed: PCL and Open3D read the real capture's frame as the binary one",
          "[pcd][tools][real]") {
  const std::optional<RealFrame> frame = real_frame();
  if (!frame) return;
  test::ScratchDir dir("pcd-compressed-tools");
  PcdCompressor compressor;
  compressor.reserve(frame->points.size(), PcdLayout::kAutoware);
  std::string pairs;
  for (const PcdLayout layout : kLayouts) {
    INFO(to_string(layout));
    const std::string name(to_string(layout));
    const PcdFormat format{layout, Axes::kHesai};
    const std::string binary = binary_pcd(frame->points, format, frame->context);
    const std::string compressed =
        compressed_pcd(compressor, frame->points, format, frame->context);
    write_pcd_bytes(dir / (name + ".pcd"), binary);
    write_pcd_bytes(dir / (name + "_lzf.pcd"), compressed);
    pairs += " '" + (dir / (name + ".pcd")).string() + "' '" +
             (dir / (name + "_lzf.pcd")).string() + "'";
    // PCL's reader (pcl_convert_pcd_ascii_binary, format 0: ASCII) makes the same text of both.
    for (const std::string& file : {name, name + "_lzf"}) {
      const auto r =
          test::run_command("pcl_convert_pcd_ascii_binary '" + (dir / (file + ".pcd")).string() +
                            "' '" + (dir / (file + ".txt")).string() + "' 0 2>&1");
      INFO(r.out);
      REQUIRE(r.exit_code == 0);
    }
    const std::string ascii = harness::read_file(dir / (name + ".txt"));
    CHECK(ascii.find("\nPOINTS " + std::to_string(frame->points.size()) + "\n") !=
          std::string::npos);
    CHECK(static_cast<std::size_t>(std::count(ascii.begin(), ascii.end(), '\n')) >
          frame->points.size());
    CHECK(harness::read_file(dir / (name + "_lzf.txt")) == ascii);
  }
  // Open3D's tensor reader: every field of each compressed file equals the binary file's.
  const auto r = test::run_command(
      "/usr/bin/python3 -c '"
      "import json, sys, numpy, open3d as o3d\n"
      "out = {}\n"
      "for binary, compressed in zip(sys.argv[1::2], sys.argv[2::2]):\n"
      "    a = o3d.t.io.read_point_cloud(binary).point\n"
      "    b = o3d.t.io.read_point_cloud(compressed).point\n"
      "    out[compressed] = {\"points\": len(a[\"positions\"]), \"fields\": sorted(a),\n"
      "        \"equal\": sorted(a) == sorted(b) and all(numpy.array_equal(a[k].numpy(),"
      " b[k].numpy()) for k in a)}\n"
      "print(json.dumps(out))'" +
      pairs + " 2>&1");
  INFO(r.out.substr(0, 2000));
  REQUIRE(r.exit_code == 0);
  const json o3d = json::parse(r.out.substr(r.out.find('{')));
  REQUIRE(o3d.size() == kLayouts.size());
  for (const auto& [file, result] : o3d.items()) {
    INFO(file);
    CHECK(result["points"] == frame->points.size());
    CHECK(result["fields"].size() >= 4);  // positions and the layout's other fields
    CHECK(result["equal"] == true);
  }
}

namespace {

// Points, by PCL's reading (pcl_convert_pcd_ascii_binary to ASCII, its data lines) and Open3D's.
std::size_t pcl_points(const fs::path& file, const fs::path& ascii) {
  const auto r = test::run_command("pcl_convert_pcd_ascii_binary '" + file.string() + "' '" +
                                   ascii.string() + "' 0 2>&1");
  INFO(r.out);
  REQUIRE(r.exit_code == 0);
  const std::string text = harness::read_file(ascii);
  const auto data = text.find("\nDATA ascii\n");
  REQUIRE(data != std::string::npos);
  return static_cast<std::size_t>(std::count(text.begin() + data + 12, text.end(), '\n'));
}
std::size_t open3d_points(const fs::path& file) {
  const auto r = test::run_command(
      "/usr/bin/python3 -c 'import sys, open3d as o3d\n"
      "print(len(o3d.t.io.read_point_cloud(sys.argv[1]).point[\"positions\"]))' '" +
      file.string() + "' 2>&1");
  INFO(r.out.substr(0, 2000));
  REQUIRE(r.exit_code == 0);
  return std::stoul(r.out.substr(r.out.find_last_of('\n', r.out.size() - 2) + 1));
}

}  // namespace

TEST_CASE("pandarcapd --pcd-compression lzf: live frames PCL and Open3D read whole",
          "[pcd][daemon][tools][realtime][threads]") {
  test::ScratchDir dir("pcd-compressed-live");
  const fs::path out = dir / "out";
  // 3 s: the writer counts its allocations after a 2 s warm-up.
  harness::ChildProcess daemon(test::binary("pandarcapd"),
                               {"--allow-root", "--simulate", "--duration", "3",
                                "--pcd-compression", "lzf", "--output-dir", out.string()},
                               dir / "log.txt");
  const auto status = daemon.wait_exit(30s);
  INFO(daemon.log());
  REQUIRE(status == 0);
  const json h = test::last_health_record(out);
  const std::vector<fs::path> frames = test::files_ending(out / "frames", ".pcd");
  REQUIRE(frames.size() >= 10);
  CHECK(test::health_counter(h, "frames_written") == frames.size());
  fs::path largest;
  std::size_t largest_points = 0;
  for (const fs::path& file : frames) {
    INFO(file);
    const std::string bytes = harness::read_file(file);
    const std::size_t points = header_numbers(split_pcd(bytes).header, "POINTS").at(0);
    CHECK(decode_compressed(bytes).size() == points * pcd_point_bytes(PcdLayout::kPcl));
    if (points > largest_points) {
      largest = file;
      largest_points = points;
    }
  }
  REQUIRE(largest_points > 50'000);  // a whole revolution of the simulated room
  CHECK(pcl_points(largest, dir / "ascii.pcd") == largest_points);
  CHECK(open3d_points(largest) == largest_points);
#if !defined(__SANITIZE_ADDRESS__) && !defined(__SANITIZE_THREAD__)
  // The compression buffers were sized at start-up: writing compressed frames allocates nothing.
  CHECK(h.at("counters").at("hot_path_allocations_by_thread").at("writer") == 0);
#endif
}

TEST_CASE("replay of the real capture with lzf: the binary frames' bytes in at most 0.7 the size",
          "[pcd][daemon][real][threads]") {
  const auto capture = test::real_capture("pandar40p_nebula_dual_600rpm_1262B.pcap");
  if (!capture) return;
  test::ScratchDir dir("pcd-compressed-replay");
  std::map<std::string, std::vector<fs::path>> frames;
  for (const std::string compression : {"none", "lzf"}) {
    const auto r =
        test::run_command(test::pandarcapd_command() + " --replay '" + capture->string() +
                          "' --top-speed --max-clock-offset 0 --pcd-compression " + compression +
                          " --output-dir '" + (dir / compression).string() + "' 2>&1");
    INFO(r.out);
    REQUIRE(r.exit_code == 0);
    frames[compression] = test::files_ending(dir / compression / "frames", ".pcd");
  }
  const std::vector<fs::path>& binary = frames["none"];
  const std::vector<fs::path>& compressed = frames["lzf"];
  REQUIRE(binary.size() >= 3);
  REQUIRE(compressed.size() == binary.size());
  std::uintmax_t binary_bytes = 0, compressed_bytes = 0;
  for (std::size_t i = 0; i < binary.size(); ++i) {
    INFO(compressed[i]);
    CHECK(compressed[i].filename() == binary[i].filename());
    CHECK(decode_compressed(harness::read_file(compressed[i])) ==
          split_pcd(harness::read_file(binary[i])).data);
    binary_bytes += fs::file_size(binary[i]);
    compressed_bytes += fs::file_size(compressed[i]);
  }
  const double ratio = static_cast<double>(compressed_bytes) / static_cast<double>(binary_bytes);
  INFO("compressed " << compressed_bytes << " B of " << binary_bytes << " B: " << ratio);
  CHECK(ratio <= 0.7);
}
