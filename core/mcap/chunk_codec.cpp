#define ZSTD_STATIC_LINKING_ONLY  // ZSTD_initStaticCCtx, ZSTD_estimateCCtxSize
#include "core/mcap/chunk_codec.hpp"

#include <lz4frame.h>
#include <zstd.h>

#include <algorithm>
#include <cstring>
#include <stdexcept>
#include <string>

namespace pandarcap::mcap {
namespace {

// 4 MB blocks, independent, and the content size in the header (the recovery and the readers
// check it against the Chunk record's before they decompress). With independent blocks and
// autoFlush LZ4F compresses straight into the output: no block buffer.
LZ4F_preferences_t lz4_preferences(int level, std::size_t content_size, bool checksum) noexcept {
  LZ4F_preferences_t p;
  std::memset(&p, 0, sizeof p);
  p.frameInfo.blockSizeID = LZ4F_max4MB;
  p.frameInfo.blockMode = LZ4F_blockIndependent;
  p.frameInfo.contentSize = content_size;
  p.frameInfo.contentChecksumFlag = checksum ? LZ4F_contentChecksumEnabled : LZ4F_noContentChecksum;
  p.compressionLevel = std::min(level, 12);
  p.autoFlush = 1;
  return p;
}

struct Lz4Decompressor {
  LZ4F_dctx* context = nullptr;
  Lz4Decompressor() noexcept {
    if (LZ4F_isError(LZ4F_createDecompressionContext(&context, LZ4F_VERSION))) context = nullptr;
  }
  ~Lz4Decompressor() {
    if (context != nullptr) LZ4F_freeDecompressionContext(context);
  }
  Lz4Decompressor(const Lz4Decompressor&) = delete;
  Lz4Decompressor& operator=(const Lz4Decompressor&) = delete;
};

}  // namespace

struct ChunkCompressor::Lz4 {
  LZ4F_cctx* context = nullptr;
  ~Lz4() {
    if (context != nullptr) LZ4F_freeCompressionContext(context);
  }
};

std::string_view compression_name(ChunkCompression compression) noexcept {
  switch (compression) {
    case ChunkCompression::kZstd:
      return "zstd";
    case ChunkCompression::kLz4:
      return "lz4";
    case ChunkCompression::kNone:
      break;
  }
  return "";
}

std::optional<ChunkCompression> parse_compression_name(std::string_view name) noexcept {
  if (name.empty()) return ChunkCompression::kNone;
  if (name == "zstd") return ChunkCompression::kZstd;
  if (name == "lz4") return ChunkCompression::kLz4;
  return std::nullopt;
}

ChunkCompressor::ChunkCompressor(ChunkCompression compression, std::size_t max_input, int level,
                                 bool checksum)
    : compression_(compression), max_input_(max_input), checksum_(checksum), level_(level) {
  if (compression == ChunkCompression::kZstd) {
    bound_ = ZSTD_compressBound(max_input);
    // Sized for inputs up to max_input at this level; the context never allocates afterwards.
    ZSTD_compressionParameters params = ZSTD_getCParams(level, max_input, 0);
    const std::size_t size = ZSTD_estimateCCtxSize_usingCParams(params);
    workspace_.reset(new std::uint8_t[size]);
    context_ = ZSTD_initStaticCCtx(workspace_.get(), size);
    if (context_ == nullptr) throw std::runtime_error("zstd: cannot set up a static context");
    auto* c = static_cast<ZSTD_CCtx*>(context_);
    // The content size in the frame header (the readers and the recovery check it), asked for:
    // a static context does not start from the defaults' flags.
    if (ZSTD_isError(ZSTD_CCtx_setParameter(c, ZSTD_c_compressionLevel, level)) ||
        ZSTD_isError(ZSTD_CCtx_setParameter(c, ZSTD_c_contentSizeFlag, 1)) ||
        ZSTD_isError(ZSTD_CCtx_setParameter(c, ZSTD_c_checksumFlag, checksum ? 1 : 0))) {
      throw std::runtime_error("zstd: cannot set the level, content size and checksum");
    }
  } else if (compression == ChunkCompression::kLz4) {
    const LZ4F_preferences_t prefs = lz4_preferences(level, max_input, checksum);
    bound_ = LZ4F_compressFrameBound(max_input, &prefs);
    lz4_ = std::make_unique<Lz4>();
    if (LZ4F_isError(LZ4F_createCompressionContext(&lz4_->context, LZ4F_VERSION))) {
      lz4_->context = nullptr;
      throw std::runtime_error("lz4: cannot create a compression context");
    }
    // LZ4F allocates its block state at the first frame: done here, not in the first chunk.
    const std::uint8_t warm[64] = {};
    std::unique_ptr<std::uint8_t[]> out(
        new std::uint8_t[LZ4F_compressFrameBound(sizeof warm, &prefs)]);
    compress(warm, std::span(out.get(), LZ4F_compressFrameBound(sizeof warm, &prefs)));
  }
}

ChunkCompressor::~ChunkCompressor() = default;

std::size_t ChunkCompressor::compress(std::span<const std::uint8_t> in,
                                      std::span<std::uint8_t> out) {
  if (compression_ == ChunkCompression::kLz4) {
    const LZ4F_preferences_t prefs = lz4_preferences(level_, in.size(), checksum_);
    if (in.size() > max_input_ || out.size() < LZ4F_compressFrameBound(in.size(), &prefs)) {
      throw std::length_error("lz4: chunk larger than the compressor was sized for");
    }
    LZ4F_cctx* c = lz4_->context;
    std::size_t n = LZ4F_compressBegin(c, out.data(), out.size(), &prefs);
    if (!LZ4F_isError(n)) {
      const std::size_t body =
          LZ4F_compressUpdate(c, out.data() + n, out.size() - n, in.data(), in.size(), nullptr);
      n = LZ4F_isError(body) ? body : n + body;
    }
    if (!LZ4F_isError(n)) {
      const std::size_t end = LZ4F_compressEnd(c, out.data() + n, out.size() - n, nullptr);
      n = LZ4F_isError(end) ? end : n + end;
    }
    if (LZ4F_isError(n)) throw std::runtime_error(std::string("lz4: ") + LZ4F_getErrorName(n));
    return n;
  }
  if (compression_ != ChunkCompression::kZstd) throw std::logic_error("no compression to run");
  if (in.size() > max_input_ || out.size() < ZSTD_compressBound(in.size())) {
    throw std::length_error("zstd: chunk larger than the compressor was sized for");
  }
  // compress2 applies the context's parameters (the level and the checksum flag, set once).
  const std::size_t n = ZSTD_compress2(static_cast<ZSTD_CCtx*>(context_), out.data(), out.size(),
                                       in.data(), in.size());
  if (ZSTD_isError(n)) throw std::runtime_error(std::string("zstd: ") + ZSTD_getErrorName(n));
  return n;
}

std::optional<std::uint64_t> stored_content_size(std::string_view compression,
                                                 std::span<const std::uint8_t> stored) noexcept {
  if (compression.empty()) return stored.size();
  if (compression == "lz4") {
    Lz4Decompressor d;
    if (d.context == nullptr) return std::nullopt;
    LZ4F_frameInfo_t info;
    std::size_t consumed = stored.size();
    const std::size_t r = LZ4F_getFrameInfo(d.context, &info, stored.data(), &consumed);
    // contentSize 0: the header does not say (a frame of 0 bytes states nothing either).
    if (LZ4F_isError(r) || info.contentSize == 0) return std::nullopt;
    return info.contentSize;
  }
  if (compression != "zstd") return std::nullopt;
  const unsigned long long content = ZSTD_getFrameContentSize(stored.data(), stored.size());
  if (content == ZSTD_CONTENTSIZE_UNKNOWN || content == ZSTD_CONTENTSIZE_ERROR) return std::nullopt;
  return content;
}

namespace {

bool decompress_lz4(std::span<const std::uint8_t> stored, std::span<std::uint8_t> out) noexcept {
  Lz4Decompressor d;
  if (d.context == nullptr) return false;
  std::size_t in_at = 0, out_at = 0;
  while (true) {
    std::size_t in_size = stored.size() - in_at, out_size = out.size() - out_at;
    const std::size_t hint = LZ4F_decompress(d.context, out.data() + out_at, &out_size,
                                             stored.data() + in_at, &in_size, nullptr);
    if (LZ4F_isError(hint)) return false;
    in_at += in_size;
    out_at += out_size;
    if (hint == 0) break;  // the frame's end: checked against its content size by LZ4F
    if (in_size == 0 && out_size == 0) return false;  // cut: no progress possible
  }
  return in_at == stored.size() && out_at == out.size();
}

}  // namespace

bool decompress_chunk(std::string_view compression, std::span<const std::uint8_t> stored,
                      std::span<std::uint8_t> out) noexcept {
  if (compression.empty()) {
    if (stored.size() != out.size()) return false;
    if (!out.empty()) std::memcpy(out.data(), stored.data(), out.size());
    return true;
  }
  if (compression == "lz4") {
    return stored_content_size(compression, stored) == out.size() && decompress_lz4(stored, out);
  }
  if (compression != "zstd") return false;
  const unsigned long long content = ZSTD_getFrameContentSize(stored.data(), stored.size());
  if (content != out.size()) return false;
  const std::size_t n = ZSTD_decompress(out.data(), out.size(), stored.data(), stored.size());
  return !ZSTD_isError(n) && n == out.size();
}

}  // namespace pandarcap::mcap
