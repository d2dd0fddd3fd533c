// PCD "DATA binary_compressed", byte for byte as the Point Cloud Library writes and reads it
// (pcl::PCDWriter::writeBinaryCompressed, PCDReader::readBodyBinary), in any field layout:
//
//   <the layout's header, ending "DATA binary_compressed\n">
//   compressed size U4 | uncompressed size U4 (= points x point bytes) | LZF data
//
// The LZF data is liblzf's lzf_compress of the points transposed to field-major order: every
// point's x, then every point's y, ..., each field's values packed in point order. A column of
// one field (channels 0..39 over and over, return types, nearby times) repeats where rows of
// mixed fields do not, which is what LZF finds. No points: both sizes 0 and no data, as PCL
// writes it. There is no stored-uncompressed fallback in the format: data that does not shrink is
// still LZF (liblzf writes it as literal runs, at most ~3 % larger), as PCL does.
//
// Open3D reads it too. Sizes are 32-bit: a frame must stay under 4 GiB (arenas.points_per_frame
// caps it at 10 million points, 320 MB in the widest layout).
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "core/frames/pcd.hpp"
#include "core/frames/point.hpp"

namespace pandarcap {

// The bytes the compressed data section can take for `points` points of `layout`, sizes
// included: the room compress() needs.
std::size_t pcd_compressed_bound(std::size_t points, PcdLayout layout) noexcept;

// Encodes frames as binary_compressed data sections with buffers it keeps: once reserve() has
// sized them for the largest frame, compressing allocates nothing. Not thread-safe; one per
// writer.
class PcdCompressor {
 public:
  // Sizes the buffers for frames of up to `max_points` points in `layout`.
  void reserve(std::size_t max_points, PcdLayout layout);

  // The data section for `points` (what follows "DATA binary_compressed\n"): the two sizes and
  // the LZF data. A view of this object's buffer, valid until the next call. A frame larger than
  // reserved grows the buffers (allocates). Throws std::runtime_error if LZF fails, which the
  // bound rules out.
  std::span<const std::uint8_t> compress(std::span<const Point> points, PcdFormat format,
                                         PcdFrameContext frame);
  // The same for points already encoded as rows of `layout` (a frame arena's bytes).
  std::span<const std::uint8_t> compress_rows(std::span<const std::uint8_t> rows, PcdLayout layout);

 private:
  // Rows of points first..first+n of a `total`-point frame into their columns.
  void scatter(std::span<const std::uint8_t> rows, std::size_t first, std::size_t total,
               PcdLayout layout);
  std::span<const std::uint8_t> finish(std::size_t points, PcdLayout layout);

  std::vector<std::uint8_t> rows_;     // one chunk of points, encoded as rows
  std::vector<std::uint8_t> columns_;  // the whole frame, field-major
  std::vector<std::uint8_t> out_;      // sizes + LZF data
};

}  // namespace pandarcap
