#include "core/frames/topdown_render.hpp"

#include <algorithm>
#include <cmath>

namespace pandarcap {

namespace {

struct Rgb {
  std::uint8_t r, g, b;
};

// 0..1 to blue, cyan, green, yellow, red: distinguishable on a dark background, and in order.
Rgb scale_colour(double t) noexcept {
  t = std::clamp(t, 0.0, 1.0);
  constexpr Rgb stops[] = {
      {40, 80, 255}, {0, 220, 255}, {40, 230, 60}, {255, 230, 0}, {255, 40, 20}};
  const double at = t * 4;
  const int i = std::min(static_cast<int>(at), 3);
  const double f = at - i;
  const auto mix = [f](std::uint8_t a, std::uint8_t b) {
    return static_cast<std::uint8_t>(std::lround(a + (b - a) * f));
  };
  return {mix(stops[i].r, stops[i + 1].r), mix(stops[i].g, stops[i + 1].g),
          mix(stops[i].b, stops[i + 1].b)};
}

void put_pixel(RgbImage& image, int col, int row, Rgb c) noexcept {
  if (col < 0 || row < 0 || col >= image.width || row >= image.height) return;
  std::uint8_t* p = image.rgb.data() + (static_cast<std::size_t>(row) * image.width + col) * 3;
  p[0] = c.r;
  p[1] = c.g;
  p[2] = c.b;
}

}  // namespace

bool top_down_pixel(const TopDownOptions& o, double x, double y, int& col, int& row) noexcept {
  const double scale = o.size_px / (2 * o.half_width_m);  // pixels per metre
  const double c = std::floor((x + o.half_width_m) * scale);
  const double r = std::floor((o.half_width_m - y) * scale);
  if (!(c >= 0 && r >= 0 && c < o.size_px && r < o.size_px)) return false;
  col = static_cast<int>(c);
  row = static_cast<int>(r);
  return true;
}

RgbImage render_top_down(std::span<const Point> points, const TopDownOptions& o) {
  RgbImage image;
  image.width = image.height = o.size_px;
  image.rgb.resize(static_cast<std::size_t>(o.size_px) * o.size_px * 3);
  for (std::size_t i = 0; i < image.rgb.size(); i += 3) {
    std::copy(std::begin(kTopDownBackground), std::end(kTopDownBackground), image.rgb.begin() + i);
  }
  // The grid: a line every grid_m metres, those through the sensor brighter.
  const double scale = o.size_px / (2 * o.half_width_m);
  const int lines = static_cast<int>(std::floor(o.half_width_m / o.grid_m));
  for (int k = -lines; k <= lines; ++k) {
    const Rgb c = k == 0 ? Rgb{90, 90, 110} : Rgb{48, 48, 62};
    const int at = static_cast<int>(std::floor((o.half_width_m + k * o.grid_m) * scale));
    for (int i = 0; i < o.size_px; ++i) {
      put_pixel(image, at, i, c);  // x = k * grid
      put_pixel(image, i, at, c);  // y = k * grid
    }
  }
  for (const Point& p : points) {
    int col = 0, row = 0;
    if (!top_down_pixel(o, p.x, p.y, col, row)) continue;
    const double t = o.colour == TopDownOptions::Colour::kHeight
                         ? (p.z - o.height_min_m) / (o.height_max_m - o.height_min_m)
                         : p.intensity / 255.0;
    const Rgb c = scale_colour(t);
    for (int dr = 0; dr < 2; ++dr)
      for (int dc = 0; dc < 2; ++dc)
        put_pixel(image, col + dc, row + dr, c);
  }
  // The sensor's axes, on top: +x red, +y green, 2 m long, 3 pixels wide.
  const int centre = static_cast<int>(std::floor(o.half_width_m * scale));
  const int length = std::max(static_cast<int>(2 * scale), 6);
  for (int i = 0; i <= length; ++i) {
    for (int w = -1; w <= 1; ++w) {
      put_pixel(image, centre + i, centre + w, Rgb{255, 60, 60});
      put_pixel(image, centre + w, centre - i, Rgb{60, 255, 60});
    }
  }
  return image;
}

}  // namespace pandarcap
