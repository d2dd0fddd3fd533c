// A zstd-compressed file read as a plain stdio stream (fopencookie): what libpcap reads a
// compressed capture (raw/NAME.pcap.zst) through, decompressing as it goes.
//
// Memory is bounded: one input buffer (ZSTD_DStreamInSize, 128 KiB) and zstd's window (at most
// 2^27 bytes = 128 MiB, the zstd command's own default limit; pandarcap's recorder and
// `zstd -1..-19` use 1-8 MiB). The file is never read whole. Several concatenated frames (and
// skippable frames) read as one stream, as `zstd -d` does.
//
// How the stream ends, for the caller to tell apart after libpcap has stopped:
//   - the last frame is finished: a clean end;
//   - the file ends inside a frame (a recording killed before its last ZSTD_e_end: NAME.pcap.zst
//     .part): everything flushed before the cut is delivered, then end of stream, and
//     unfinished_frame() says so;
//   - the bytes do not decompress, or a frame's content checksum (pandarcapd writes one) does not
//     match: the read fails (EIO) and error() names zstd's reason and the byte it was found at.
#pragma once

#include <sys/types.h>

#include <cstdint>
#include <cstdio>
#include <string>

namespace pandarcap {

class ZstdReadStream {
 public:
  // Wraps `fd` (owned from here: closed with the FILE, or now if this throws) in a FILE* that
  // yields the decompressed bytes. `state` is set to the stream's state, which lives until the
  // FILE is closed. Throws std::runtime_error when zstd cannot be set up.
  static std::FILE* open(int fd, const ZstdReadStream*& state);

  bool unfinished_frame() const noexcept { return in_frame_; }
  // Why the stream failed: "" while it has not.
  const std::string& error() const noexcept { return error_; }

  ~ZstdReadStream();
  ZstdReadStream(const ZstdReadStream&) = delete;
  ZstdReadStream& operator=(const ZstdReadStream&) = delete;

 private:
  explicit ZstdReadStream(int fd);
  ssize_t read(char* out, std::size_t size);  // as cookie_read_function_t

  static ssize_t read_cookie(void* cookie, char* out, std::size_t size);
  static int close_cookie(void* cookie);

  int fd_;
  void* stream_ = nullptr;  // ZSTD_DStream, kept out of this header
  char* input_ = nullptr;
  std::size_t input_capacity_ = 0;
  std::size_t input_size_ = 0, input_pos_ = 0;
  std::uint64_t file_offset_ = 0;  // of input_[0] in the file
  bool eof_ = false;
  bool in_frame_ = false;  // inside a frame: begun and not yet finished
  std::string error_;
};

}  // namespace pandarcap
