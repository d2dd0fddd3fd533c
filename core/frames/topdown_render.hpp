// A top-down picture of one frame: what a newcomer wants to see first, and what a test can check
// without a display. Pure: points in, an RGB raster out (the PNG encoding is the caller's:
// pandarcap-inspect --png, with libpng).
//
// The view looks down the sensor's z axis, in its own axes: azimuth 0 (+y) points up the image,
// +x (azimuth 90°) to the right, the sensor at the centre. A grid line every `grid_m` metres
// (the ones through the sensor brighter), the sensor's axes drawn from the centre (+x red, +y
// green, 2 m long), and each point a 2x2 dot coloured by its height or intensity on a
// blue-green-yellow-red scale. Points outside the square are left out.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "core/frames/point.hpp"

namespace pandarcap {

struct TopDownOptions {
  int size_px = 800;         // the image is size_px x size_px
  double half_width_m = 30;  // the image spans [-half_width_m, +half_width_m] in x and y
  double grid_m = 5;         // a grid line every grid_m metres
  enum class Colour : std::uint8_t { kHeight, kIntensity } colour = Colour::kHeight;
  double height_min_m = -2.5;  // the colour scale's ends, by height
  double height_max_m = 3.0;
};

struct RgbImage {
  int width = 0, height = 0;
  std::vector<std::uint8_t> rgb;  // row-major, 3 bytes a pixel, top row first
  const std::uint8_t* pixel(int col, int row) const noexcept {
    return rgb.data() + (static_cast<std::size_t>(row) * static_cast<std::size_t>(width) +
                         static_cast<std::size_t>(col)) *
                            3;
  }
};

inline constexpr std::uint8_t kTopDownBackground[3] = {16, 16, 24};

// The pixel a point at (x, y) metres falls on; false when outside the image.
bool top_down_pixel(const TopDownOptions& options, double x, double y, int& col, int& row) noexcept;

RgbImage render_top_down(std::span<const Point> points, const TopDownOptions& options);

}  // namespace pandarcap
