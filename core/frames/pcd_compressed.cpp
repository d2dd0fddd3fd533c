#include "core/frames/pcd_compressed.hpp"

#include <lzf.h>

#include <algorithm>
#include <cstring>
#include <stdexcept>

namespace pandarcap {
namespace {

constexpr std::size_t kChunkPoints = 4096;  // rows encoded at a time, then scattered to columns
constexpr std::size_t kSizesBytes = 8;      // compressed size U4, uncompressed size U4

// Copies `n` values of `Size` bytes from rows `step` bytes apart into a packed column.
template <std::size_t Size>
void gather(const std::uint8_t* row, std::size_t step, std::size_t n, std::uint8_t* column) {
  for (std::size_t k = 0; k < n; ++k, row += step, column += Size) {
    std::memcpy(column, row, Size);
  }
}

void gather(std::size_t size, const std::uint8_t* row, std::size_t step, std::size_t n,
            std::uint8_t* column) {
  switch (size) {
    case 1:
      return gather<1>(row, step, n, column);
    case 2:
      return gather<2>(row, step, n, column);
    case 4:
      return gather<4>(row, step, n, column);
    default:
      return gather<8>(row, step, n, column);
  }
}

void put_u32(std::uint8_t* p, std::size_t value) noexcept {
  const auto v = static_cast<std::uint32_t>(value);
  std::memcpy(p, &v, sizeof v);
}

}  // namespace

std::size_t pcd_compressed_bound(std::size_t points, PcdLayout layout) noexcept {
  // liblzf's worst case is under 104 % of the input (one control byte per 32 literals, plus a
  // few at the end).
  const std::size_t data = points * pcd_point_bytes(layout);
  return kSizesBytes + data + data / 16 + 64;
}

void PcdCompressor::reserve(std::size_t max_points, PcdLayout layout) {
  const std::size_t step = pcd_point_bytes(layout);
  rows_.resize(std::max(rows_.size(), kChunkPoints * kMaxPcdPointBytes));
  columns_.resize(std::max(columns_.size(), max_points * step));
  out_.resize(std::max(out_.size(), pcd_compressed_bound(max_points, layout)));
}

std::span<const std::uint8_t> PcdCompressor::compress(std::span<const Point> points,
                                                      PcdFormat format, PcdFrameContext frame) {
  reserve(points.size(), format.layout);  // nothing to do for a frame within the reserve
  const std::size_t n = points.size();
  for (std::size_t first = 0; first < n; first += kChunkPoints) {
    const std::size_t count = std::min(kChunkPoints, n - first);
    const std::size_t bytes = encode_pcd_points(points.subspan(first, count), rows_, format, frame);
    scatter(std::span<const std::uint8_t>(rows_.data(), bytes), first, n, format.layout);
  }
  return finish(n, format.layout);
}

std::span<const std::uint8_t> PcdCompressor::compress_rows(std::span<const std::uint8_t> rows,
                                                           PcdLayout layout) {
  const std::size_t n = rows.size() / pcd_point_bytes(layout);
  reserve(n, layout);
  scatter(rows, 0, n, layout);
  return finish(n, layout);
}

void PcdCompressor::scatter(std::span<const std::uint8_t> rows, std::size_t first,
                            std::size_t total, PcdLayout layout) {
  const std::size_t step = pcd_point_bytes(layout);
  const std::size_t count = rows.size() / step;
  // Field f's column starts after the columns before it: `total` values of each.
  std::size_t column_start = 0;
  for (const PcdField& field : pcd_fields(layout)) {
    gather(field.size, rows.data() + field.offset, step, count,
           columns_.data() + column_start + first * field.size);
    column_start += total * field.size;
  }
}

std::span<const std::uint8_t> PcdCompressor::finish(std::size_t points, PcdLayout layout) {
  const std::size_t data = points * pcd_point_bytes(layout);
  std::size_t compressed = 0;
  if (data > 0) {
    compressed =
        lzf_compress(columns_.data(), static_cast<unsigned>(data), out_.data() + kSizesBytes,
                     static_cast<unsigned>(out_.size() - kSizesBytes));
    if (compressed == 0) throw std::runtime_error("LZF compression of a PCD frame failed");
  }
  put_u32(out_.data(), compressed);
  put_u32(out_.data() + 4, data);
  return std::span<const std::uint8_t>(out_.data(), kSizesBytes + compressed);
}

}  // namespace pandarcap
