// Chunk compression for MCAP files, through libzstd (Debian's libzstd-dev).
//
// The compressor's state lives in one workspace allocated when it is made (ZSTD_initStaticCCtx),
// so compressing a chunk in the writer thread never allocates. Decompression is for the recovery
// at start-up and for tests.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string_view>

namespace pandarcap::mcap {

class ChunkCompressor {
 public:
  // `max_input` bounds what one compress() call takes. Level 1 (the default) is zstd's fastest
  // standard level and roughly halves a Pandar40P's messages (1.9x); negative levels trade
  // ratio for speed (zstd --fast=N: -3 gives 1.7x at ~1.7 times level 1's speed).
  explicit ChunkCompressor(std::size_t max_input, int level = 1);
  ~ChunkCompressor();
  ChunkCompressor(const ChunkCompressor&) = delete;
  ChunkCompressor& operator=(const ChunkCompressor&) = delete;

  // Compresses `in` (at most max_input bytes) into `out`, which holds bound() bytes; returns the
  // compressed size. Throws std::runtime_error on a zstd error (none is expected).
  std::size_t compress(std::span<const std::uint8_t> in, std::span<std::uint8_t> out);
  std::size_t bound() const noexcept { return bound_; }

 private:
  std::unique_ptr<std::uint8_t[]> workspace_;
  void* context_ = nullptr;  // ZSTD_CCtx, inside workspace_
  std::size_t max_input_, bound_;
  int level_;
};

// Decompresses a chunk's records stored with `compression` ("" or "zstd") into `out`, which must
// be exactly the chunk's uncompressed size. False when the compression is unknown or the bytes do
// not decompress to exactly that size (a damaged or cut chunk).
// The size `stored` says it decompresses to (its zstd frame header's content size), read without
// decompressing; nothing when the compression is unknown or the header does not say.
std::optional<std::uint64_t> stored_content_size(std::string_view compression,
                                                 std::span<const std::uint8_t> stored) noexcept;

bool decompress_chunk(std::string_view compression, std::span<const std::uint8_t> stored,
                      std::span<std::uint8_t> out) noexcept;

}  // namespace pandarcap::mcap
