// pandarcap-inspect --png: the top-down picture (core/frames/topdown_render.hpp) drawn where the
// points are and nowhere else, and the PNG as libpng reads it back.
#include <png.h>

#include <catch2/catch.hpp>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "core/frames/frame_collector.hpp"
#include "core/frames/topdown_render.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
namespace fs = std::filesystem;

namespace {

bool background(const std::uint8_t* p) {
  return std::memcmp(p, kTopDownBackground, 3) == 0;
}

// A PNG as libpng reads it, in RGB.
RgbImage read_png(const fs::path& path) {
  png_image png;
  std::memset(&png, 0, sizeof png);
  png.version = PNG_IMAGE_VERSION;
  REQUIRE(png_image_begin_read_from_file(&png, path.c_str()) != 0);
  png.format = PNG_FORMAT_RGB;
  RgbImage image;
  image.width = static_cast<int>(png.width);
  image.height = static_cast<int>(png.height);
  image.rgb.resize(PNG_IMAGE_SIZE(png));
  REQUIRE(png_image_finish_read(&png, nullptr, image.rgb.data(), 0, nullptr) != 0);
  return image;
}

}  // namespace

TEST_CASE("top-down render: points where they are, axes from the centre, background elsewhere",
          "[png]") {
  TopDownOptions o;
  o.size_px = 200;
  o.half_width_m = 10;  // 10 pixels a metre
  std::vector<Point> points(2);
  points[0].x = 5;  // right of the sensor, at azimuth 90°
  points[0].y = 0.5;
  points[0].z = 3;  // high: red end of the height scale
  points[1].x = -7;
  points[1].y = 8;     // ahead-left
  points[1].z = -2.5;  // low: blue end
  const RgbImage image = render_top_down(points, o);
  REQUIRE(image.width == 200);
  REQUIRE(image.rgb.size() == 200u * 200u * 3u);
  int col = 0, row = 0;
  REQUIRE(top_down_pixel(o, 5, 0.5, col, row));
  CHECK(col == 150);
  CHECK(row == 95);
  const std::uint8_t* high = image.pixel(col, row);
  CHECK(high[0] > 200);  // red
  CHECK(high[2] < 60);
  REQUIRE(top_down_pixel(o, -7, 8, col, row));
  CHECK(col == 30);
  CHECK(row == 20);
  const std::uint8_t* low = image.pixel(col, row);
  CHECK(low[2] > 200);  // blue
  CHECK(low[0] < 60);
  // The axes: +x red to the right of the centre, +y green above it.
  CHECK(image.pixel(110, 100)[0] == 255);
  CHECK(image.pixel(100, 90)[1] == 255);
  // Away from the points, the axes and the grid (every 5 m = 50 px): background.
  CHECK(background(image.pixel(125, 175)));
  CHECK(background(image.pixel(20, 180)));
  // A point outside the square is left out.
  CHECK_FALSE(top_down_pixel(o, 10.5, 0, col, row));
}

TEST_CASE("pandarcap-inspect --png draws the real capture's frame where its points are",
          "[png][real]") {
  const auto capture = test::real_capture("pandar40p_nebula_dual_600rpm_1262B.pcap");
  const auto calibration = test::real_capture("nebula_Pandar40P_calibration.csv");
  if (!capture || !calibration) return;
  test::ScratchDir dir("inspect-png");
  const fs::path png = dir / "frame.png";
  const auto r = test::run_command(
      test::binary("pandarcap-inspect").string() + " --summary --png-range 6 --calibration '" +
      calibration->string() + "' --png '" + png.string() + "' '" + capture->string() + "' 2>&1");
  INFO(r.out);
  REQUIRE(r.exit_code == 0);
  CHECK(r.out.find("drew a complete frame of 56762 points") != std::string::npos);
  const RgbImage image = read_png(png);
  REQUIRE(image.width == 800);
  REQUIRE(image.height == 800);

  // The same frame decoded here: the largest complete one.
  std::vector<Point> frame;
  FrameCollector collector(3, kDefaultFrameCapacityPoints, [&](const Frame& f) {
    if (!f.info.partial && f.size > frame.size()) frame.assign(f.used().begin(), f.used().end());
  });
  test::decode_capture(*capture, *calibration, collector);
  REQUIRE(frame.size() == 56762);

  TopDownOptions o;
  o.half_width_m = 6;
  std::size_t inside = 0, drawn = 0;
  for (std::size_t i = 0; i < frame.size(); i += 37) {
    int col = 0, row = 0;
    if (!top_down_pixel(o, frame[i].x, frame[i].y, col, row)) continue;
    ++inside;
    if (!background(image.pixel(col, row))) ++drawn;
  }
  REQUIRE(inside > 1000);
  CHECK(drawn == inside);  // every point in view is drawn
  // ... and the picture is not painted over: most of it is background.
  std::size_t background_pixels = 0;
  for (int row = 0; row < image.height; ++row)
    for (int col = 0; col < image.width; ++col)
      background_pixels += background(image.pixel(col, row)) ? 1 : 0;
  const auto all = static_cast<std::size_t>(image.width) * static_cast<std::size_t>(image.height);
  CHECK(background_pixels * 10 > all * 6);
  CHECK(background_pixels * 100 < all * 99);
}

TEST_CASE("pandarcap-inspect --png: an unwritable path and a bad colour are clear errors",
          "[png]") {
  test::ScratchDir dir("inspect-png-errors");
  const std::string inspect = test::binary("pandarcap-inspect").string();
  // A capture of the simulated sensor is not needed for the option check: it fails first.
  const auto colour = test::run_command(inspect + " --png x.png --png-colour rainbow x.pcap 2>&1");
  CHECK(colour.exit_code == 64);
  CHECK(colour.out.find("\"rainbow\" is not one of height, intensity") != std::string::npos);
  const auto capture = test::real_capture("pandar40p_nebula_dual_600rpm_1262B.pcap");
  if (!capture) return;
  const auto r =
      test::run_command(inspect + " --summary --png '" + (dir / "no-such-dir" / "x.png").string() +
                        "' '" + capture->string() + "' 2>&1");
  CHECK(r.exit_code == 2);
  CHECK(r.out.find("no-such-dir/x.png: cannot write the PNG") != std::string::npos);
}
