#include "daemon/pcap/zstd_read_stream.hpp"

#include <unistd.h>
#include <zstd.h>
#include <zstd_errors.h>

#include <cerrno>
#include <cstring>
#include <memory>
#include <stdexcept>

namespace pandarcap {
namespace {

// The largest window a frame may ask for: zstd's own default limit (ZSTD_WINDOWLOG_LIMIT_DEFAULT),
// which `zstd -d` also applies. A frame asking for more is refused ("Frame requires too much
// memory for decoding"), so a crafted header cannot make the reader allocate more.
constexpr int kWindowLogMax = 27;

ZSTD_DStream* dstream(void* p) noexcept {
  return static_cast<ZSTD_DStream*>(p);
}

}  // namespace

ZstdReadStream::ZstdReadStream(int fd) : fd_(fd) {}

ZstdReadStream::~ZstdReadStream() {
  ZSTD_freeDStream(dstream(stream_));
  delete[] input_;
  if (fd_ >= 0) ::close(fd_);
}

std::FILE* ZstdReadStream::open(int fd, const ZstdReadStream*& state) {
  std::unique_ptr<ZstdReadStream> self(new ZstdReadStream(fd));
  self->stream_ = ZSTD_createDStream();
  if (self->stream_ == nullptr)
    throw std::runtime_error("zstd: cannot create a decompression stream");
  ZSTD_DCtx_setParameter(dstream(self->stream_), ZSTD_d_windowLogMax, kWindowLogMax);
  self->input_capacity_ = ZSTD_DStreamInSize();
  self->input_ = new char[self->input_capacity_];
  const cookie_io_functions_t functions{&ZstdReadStream::read_cookie, nullptr, nullptr,
                                        &ZstdReadStream::close_cookie};
  std::FILE* file = ::fopencookie(self.get(), "rb", functions);
  if (file == nullptr)
    throw std::runtime_error(std::string("fopencookie: ") + std::strerror(errno));
  // stdio's requests as large as zstd's blocks: fewer calls, same memory bound.
  std::setvbuf(file, nullptr, _IOFBF, ZSTD_DStreamOutSize());
  state = self.release();  // the FILE owns it from here (close_cookie)
  return file;
}

ssize_t ZstdReadStream::read_cookie(void* cookie, char* out, std::size_t size) {
  return static_cast<ZstdReadStream*>(cookie)->read(out, size);
}

int ZstdReadStream::close_cookie(void* cookie) {
  delete static_cast<ZstdReadStream*>(cookie);
  return 0;
}

ssize_t ZstdReadStream::read(char* out, std::size_t size) {
  if (!error_.empty()) {
    errno = EIO;
    return -1;
  }
  ZSTD_outBuffer output{out, size, 0};
  while (output.pos == 0) {
    if (input_pos_ == input_size_ && !eof_) {
      ssize_t got;
      do {
        got = ::read(fd_, input_, input_capacity_);
      } while (got < 0 && errno == EINTR);
      if (got < 0) {
        error_ = std::string("cannot read: ") + std::strerror(errno);
        errno = EIO;
        return -1;
      }
      file_offset_ += input_size_;  // the buffer's bytes before these
      input_size_ = static_cast<std::size_t>(got);
      input_pos_ = 0;
      eof_ = got == 0;
    }
    ZSTD_inBuffer input{input_, input_size_, input_pos_};
    const std::size_t hint = ZSTD_decompressStream(dstream(stream_), &output, &input);
    if (ZSTD_isError(hint)) {
      // Where, in the file's (compressed) bytes: the input zstd had reached. A checksum that does
      // not match is found at the frame's end, after the frame's bytes were handed on.
      const std::uint64_t at = file_offset_ + input.pos;
      error_ = ZSTD_getErrorCode(hint) == ZSTD_error_checksum_wrong
                   ? "the zstd frame's content checksum does not match what it "
                     "decompresses to (the frame ending at byte " +
                         std::to_string(at) + ")"
                   : "corrupt zstd data (" + std::string(ZSTD_getErrorName(hint)) + ") near byte " +
                         std::to_string(at);
      errno = EIO;
      return -1;
    }
    // Only a call that moved bytes says where in a frame the stream is: 0 = a frame just ended.
    if (input.pos != input_pos_ || output.pos != 0) in_frame_ = hint != 0;
    input_pos_ = input.pos;
    // Nothing more will come: everything before the end was delivered; a frame may be unfinished.
    if (output.pos == 0 && eof_ && input_pos_ == input_size_) break;
  }
  return static_cast<ssize_t>(output.pos);
}

}  // namespace pandarcap
