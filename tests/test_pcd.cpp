// PCD v0.7 binary frames: the header PCL expects and the 23-byte packed point records.
#include <array>
#include <catch2/catch.hpp>
#include <cstring>
#include <map>
#include <sstream>
#include <vector>

#include "core/frames/pcd.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;

TEST_CASE("PCD header keys come in PCL's order and describe 23-byte points", "[pcd]") {
  const std::string header = pcd_header(56723);
  std::istringstream in(header);
  std::vector<std::string> keys;
  std::string line;
  std::map<std::string, std::string> values;
  while (std::getline(in, line)) {
    if (line[0] == '#') continue;
    const auto space = line.find(' ');
    keys.push_back(line.substr(0, space));
    values[keys.back()] = line.substr(space + 1);
  }
  CHECK(keys == std::vector<std::string>{"VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH",
                                         "HEIGHT", "VIEWPOINT", "POINTS", "DATA"});
  CHECK(values["VERSION"] == "0.7");
  CHECK(values["FIELDS"] == "x y z intensity channel return_type timestamp");
  CHECK(values["WIDTH"] == "56723");
  CHECK(values["HEIGHT"] == "1");
  CHECK(values["POINTS"] == "56723");
  CHECK(values["DATA"] == "binary");
  int bytes = 0;
  std::istringstream sizes(values["SIZE"]);
  for (int size; sizes >> size;)
    bytes += size;
  CHECK(bytes == static_cast<int>(kPcdPointBytes));
  CHECK(header.back() == '\n');
}

TEST_CASE("PCD points encode every field and decode back", "[pcd]") {
  std::array<Point, 3> points{};
  points[0] = {1.5f,
               -2.25f,
               0.125f,
               2.7f,
               1'700'000'000'123'456'000,
               9104,
               200,
               39,
               ReturnType::kLastStrongest,
               {}};
  points[1] = {-100.f, 50.f, -3.f, 112.f, 1'700'000'000'999'999'000, 0, 0, 0, ReturnType::kLast,
               {}};
  points[2] = {0, 0, 0, 0, 0, 35999, 255, 7, ReturnType::kStrongest, {}};
  std::vector<std::uint8_t> bytes(points.size() * kPcdPointBytes + 5, 0xAB);
  CHECK(encode_pcd_points(points, bytes) == points.size() * kPcdPointBytes);
  CHECK(bytes[points.size() * kPcdPointBytes] == 0xAB);  // nothing written past the end
  for (std::size_t i = 0; i < points.size(); ++i) {
    const PcdPoint p = decode_pcd_point(std::span<const std::uint8_t, kPcdPointBytes>(
        bytes.data() + i * kPcdPointBytes, kPcdPointBytes));
    CHECK(p.x == points[i].x);
    CHECK(p.y == points[i].y);
    CHECK(p.z == points[i].z);
    CHECK(p.intensity == points[i].intensity);
    CHECK(p.channel == points[i].channel);
    CHECK(p.return_type == static_cast<std::uint8_t>(points[i].return_type));
    // A double holds epoch seconds to ~0.24 µs.
    CHECK(std::abs(p.timestamp_s - static_cast<double>(points[i].timestamp_ns) * 1e-9) < 1e-6);
  }
  CHECK(encode_pcd_points({}, bytes) == 0);
}

TEST_CASE("a PCD header padded to a block keeps every line and puts the points at its end",
          "[pcd]") {
  std::string header;
  append_pcd_header(header, 1234, PcdLayout::kPcl, 1'795'348'800'123'456'789);
  const std::string plain = header;
  REQUIRE(pad_pcd_header(header, 4096));
  CHECK(header.size() == 4096);
  CHECK(header.ends_with("DATA binary\n"));
  // The padding is one comment line just before VERSION; without it, the header as it was.
  const std::size_t version = header.find("\nVERSION ");
  const std::size_t padding = header.rfind('\n', version - 1) + 1;
  CHECK(header[padding] == '#');
  CHECK(header.find_first_not_of(' ', padding + 1) == version);
  CHECK(header.substr(0, padding) + header.substr(version + 1) == plain);
  std::string too_long = plain;
  CHECK_FALSE(pad_pcd_header(too_long, plain.size() + 1));
  CHECK(too_long == plain);
}
