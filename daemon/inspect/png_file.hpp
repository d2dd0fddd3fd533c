// An RGB raster written as a PNG file, with libpng's simplified API (libpng 1.6): the encoder
// is libpng's, not ours.
#pragma once

#include <string>

#include "core/frames/topdown_render.hpp"

namespace pandarcap {

// Writes `image` to `path` (replaced if there). Throws std::runtime_error naming the path and
// libpng's reason.
void write_png(const std::string& path, const RgbImage& image);

}  // namespace pandarcap
