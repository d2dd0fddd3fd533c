#define ZSTD_STATIC_LINKING_ONLY  // ZSTD_initStaticCCtx, ZSTD_estimateCCtxSize
#include "core/mcap/chunk_codec.hpp"

#include <zstd.h>

#include <algorithm>
#include <cstring>
#include <stdexcept>
#include <string>

namespace pandarcap::mcap {

ChunkCompressor::ChunkCompressor(std::size_t max_input, int level)
    : max_input_(max_input), bound_(ZSTD_compressBound(max_input)), level_(level) {
  // Sized for inputs up to max_input at this level; the context never allocates afterwards.
  ZSTD_compressionParameters params = ZSTD_getCParams(level, max_input, 0);
  const std::size_t size = ZSTD_estimateCCtxSize_usingCParams(params);
  workspace_.reset(new std::uint8_t[size]);
  context_ = ZSTD_initStaticCCtx(workspace_.get(), size);
  if (context_ == nullptr) throw std::runtime_error("zstd: cannot set up a static context");
}

ChunkCompressor::~ChunkCompressor() = default;

std::size_t ChunkCompressor::compress(std::span<const std::uint8_t> in,
                                      std::span<std::uint8_t> out) {
  if (in.size() > max_input_ || out.size() < ZSTD_compressBound(in.size())) {
    throw std::length_error("zstd: chunk larger than the compressor was sized for");
  }
  const std::size_t n = ZSTD_compressCCtx(static_cast<ZSTD_CCtx*>(context_), out.data(), out.size(),
                                          in.data(), in.size(), level_);
  if (ZSTD_isError(n)) throw std::runtime_error(std::string("zstd: ") + ZSTD_getErrorName(n));
  return n;
}

std::optional<std::uint64_t> stored_content_size(std::string_view compression,
                                                 std::span<const std::uint8_t> stored) noexcept {
  if (compression.empty()) return stored.size();
  if (compression != "zstd") return std::nullopt;
  const unsigned long long content = ZSTD_getFrameContentSize(stored.data(), stored.size());
  if (content == ZSTD_CONTENTSIZE_UNKNOWN || content == ZSTD_CONTENTSIZE_ERROR) return std::nullopt;
  return content;
}

bool decompress_chunk(std::string_view compression, std::span<const std::uint8_t> stored,
                      std::span<std::uint8_t> out) noexcept {
  if (compression.empty()) {
    if (stored.size() != out.size()) return false;
    if (!out.empty()) std::memcpy(out.data(), stored.data(), out.size());
    return true;
  }
  if (compression != "zstd") return false;
  const unsigned long long content = ZSTD_getFrameContentSize(stored.data(), stored.size());
  if (content != out.size()) return false;
  const std::size_t n = ZSTD_decompress(out.data(), out.size(), stored.data(), stored.size());
  return !ZSTD_isError(n) && n == out.size();
}

}  // namespace pandarcap::mcap
