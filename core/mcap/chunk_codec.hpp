// Chunk compression for MCAP files: zstd through libzstd (Debian's libzstd-dev), lz4 through
// liblz4 (liblz4-dev) in the LZ4 *frame* format, as the MCAP spec's compression "lz4" asks.
//
// A compressor's state is allocated when it is made (zstd: ZSTD_initStaticCCtx; lz4: its
// context, warmed by one compression so LZ4F allocates its block state then), so compressing a
// chunk never allocates. Decompression is for the recovery at start-up, the replay of MCAP
// recordings and tests.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string_view>

namespace pandarcap::mcap {

// output.mcap_compression: "none", "zstd", "lz4".
enum class ChunkCompression : std::uint8_t { kNone, kZstd, kLz4 };

// The name a Chunk record carries ("" for none, as the spec says).
std::string_view compression_name(ChunkCompression compression) noexcept;
// The record's name back (kNone for ""); nothing when pandarcap does not read it.
std::optional<ChunkCompression> parse_compression_name(std::string_view name) noexcept;

class ChunkCompressor {
 public:
  // `max_input` bounds what one compress() call takes. zstd: level 1 (the default) is zstd's
  // fastest standard level and roughly halves a Pandar40P's messages (1.9x); negative levels
  // trade ratio for speed (zstd --fast=N: -3 gives 1.7x at ~1.7 times level 1's speed).
  // lz4: the same number as LZ4F's compressionLevel: below 3 its fast mode (negative levels
  // accelerate it further), 3..12 its high-compression mode (higher levels are 12).
  // kNone: compress() is never called; bound() is 0.
  // `checksum`: the compressed data carries the codec's own checksum of what it holds (lz4: the
  // frame's content checksum, XXH32; zstd: the frame checksum, XXH64's low 32 bits), which
  // their decoders verify: what finds a damaged chunk whose MCAP CRC was not computed.
  ChunkCompressor(ChunkCompression compression, std::size_t max_input, int level = 1,
                  bool checksum = false);
  ~ChunkCompressor();
  ChunkCompressor(const ChunkCompressor&) = delete;
  ChunkCompressor& operator=(const ChunkCompressor&) = delete;

  ChunkCompression compression() const noexcept { return compression_; }
  // Compresses `in` (at most max_input bytes) into `out`, which holds bound() bytes; returns the
  // compressed size. Throws std::runtime_error on a codec error (none is expected).
  std::size_t compress(std::span<const std::uint8_t> in, std::span<std::uint8_t> out);
  std::size_t bound() const noexcept { return bound_; }

 private:
  struct Lz4;
  ChunkCompression compression_;
  std::unique_ptr<std::uint8_t[]> workspace_;
  void* context_ = nullptr;  // ZSTD_CCtx, inside workspace_
  std::unique_ptr<Lz4> lz4_;
  std::size_t max_input_, bound_ = 0;
  bool checksum_ = false;
  int level_;
};

// The size `stored` says it decompresses to (its zstd or LZ4 frame header's content size), read
// without decompressing; nothing when the compression is unknown or the header does not say.
std::optional<std::uint64_t> stored_content_size(std::string_view compression,
                                                 std::span<const std::uint8_t> stored) noexcept;

// Decompresses a chunk's records stored with `compression` ("", "zstd" or "lz4") into `out`,
// which must be exactly the chunk's uncompressed size. False when the compression is unknown or
// the bytes do not decompress to exactly that size (a damaged or cut chunk).
bool decompress_chunk(std::string_view compression, std::span<const std::uint8_t> stored,
                      std::span<std::uint8_t> out) noexcept;

}  // namespace pandarcap::mcap
