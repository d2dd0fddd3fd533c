#define ZSTD_STATIC_LINKING_ONLY  // ZSTD_initStaticCCtx, ZSTD_estimateCStreamSize
#include "daemon/pcap/zstd_write_stream.hpp"

#include <zstd.h>

#include <stdexcept>
#include <string>

namespace pandarcap {
namespace {

ZSTD_CCtx* cctx(void* context) {
  return static_cast<ZSTD_CCtx*>(context);
}

void check(std::size_t result) {
  if (ZSTD_isError(result))
    throw std::runtime_error(std::string("zstd: ") + ZSTD_getErrorName(result));
}

}  // namespace

ZstdStreamCompressor::ZstdStreamCompressor(std::size_t max_input, int level)
    : max_input_(max_input),
      // Input held back by earlier kContinue calls (at most a block) comes out with this call's.
      output_bytes_(ZSTD_compressBound(max_input + ZSTD_BLOCKSIZE_MAX) + 64),
      level_(level) {
  const std::size_t size = ZSTD_estimateCStreamSize(level);
  workspace_.reset(new std::uint8_t[size]);
  context_ = ZSTD_initStaticCCtx(workspace_.get(), size);
  if (context_ == nullptr) throw std::runtime_error("zstd: cannot set up a static context");
  output_.reset(new std::uint8_t[output_bytes_]);
  begin();
}

ZstdStreamCompressor::~ZstdStreamCompressor() = default;

void ZstdStreamCompressor::begin() noexcept {
  ZSTD_CCtx_reset(cctx(context_), ZSTD_reset_session_and_parameters);
  ZSTD_CCtx_setParameter(cctx(context_), ZSTD_c_compressionLevel, level_);
  ZSTD_CCtx_setParameter(cctx(context_), ZSTD_c_checksumFlag, 1);  // see the header
  hash_.reset();
}

std::span<const std::uint8_t> ZstdStreamCompressor::compress(std::span<const std::uint8_t> in,
                                                             Step step) {
  if (in.size() > max_input_) {
    throw std::length_error("zstd: " + std::to_string(in.size()) +
                            " bytes are more than the compressor was sized for");
  }
  hash_.update(in);
  const ZSTD_EndDirective directive = step == Step::kEnd     ? ZSTD_e_end
                                      : step == Step::kFlush ? ZSTD_e_flush
                                                             : ZSTD_e_continue;
  ZSTD_inBuffer input{in.data(), in.size(), 0};
  ZSTD_outBuffer output{output_.get(), output_bytes_, 0};
  for (;;) {
    const std::size_t remaining = ZSTD_compressStream2(cctx(context_), &output, &input, directive);
    check(remaining);
    const bool done = directive == ZSTD_e_continue ? input.pos == input.size : remaining == 0;
    if (done) break;
    if (output.pos == output.size) throw std::length_error("zstd: output buffer too small");
  }
  return {output_.get(), output.pos};
}

}  // namespace pandarcap
