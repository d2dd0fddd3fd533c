// One zstd frame written as a stream, for the compressed recordings (raw/NAME.pcap.zst): the
// pcap bytes go in as they come, and flush() ends a block so that everything given so far can be
// decompressed from the file as it stands, even if the process dies before the frame is ended.
//
// One frame per file, not a frame per flush: Debian 12's tshark (Wireshark 4.0) reads a
// one-frame .pcap.zst but stops at the end of the first frame of a file made of several. The
// frame carries zstd's content checksum (ZSTD_c_checksumFlag: XXH64 of the pcap stream, checked by
// every reader at the frame's end), so a damaged recording says so instead of replaying wrong
// packets. A recording cut back to a flush (a full disk) is ended with an empty last block
// (kZstdEmptyLastBlock) and the checksum of what it holds then: content_hash() runs beside zstd's
// own (xxh64.hpp), and PcapWriter keeps a copy of it at each flush.
//
// The compressor's state lives in one workspace allocated when it is made (ZSTD_initStaticCCtx),
// and its output in a buffer sized for the largest input; compressing never allocates, and one
// compressor serves file after file (begin()). Not thread-safe.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>

#include "daemon/pcap/xxh64.hpp"
#include "daemon/pcap/zstd_magic.hpp"

namespace pandarcap {

// A raw block of no bytes marked as the frame's last (RFC 8878 3.1.1.2): what a frame cut back
// to a block boundary needs to be complete again.
inline constexpr std::array<std::uint8_t, 3> kZstdEmptyLastBlock{0x01, 0x00, 0x00};

class ZstdStreamCompressor {
 public:
  enum class Step {
    kContinue,  // take the bytes; output may be held back
    kFlush,     // and end the block: the file so far decompresses to every byte given
    kEnd,       // and end the frame
  };

  // `max_input` bounds what one compress() call takes; `level` is zstd's (-7..19).
  ZstdStreamCompressor(std::size_t max_input, int level);
  ~ZstdStreamCompressor();
  ZstdStreamCompressor(const ZstdStreamCompressor&) = delete;
  ZstdStreamCompressor& operator=(const ZstdStreamCompressor&) = delete;

  // Starts a new frame, forgetting whatever the last one held back.
  void begin() noexcept;
  // Compresses `in` (at most max_input bytes) and returns the output produced, a view into the
  // compressor's buffer valid until the next call. Throws std::length_error for a larger input,
  // std::runtime_error on a zstd error (none is expected).
  std::span<const std::uint8_t> compress(std::span<const std::uint8_t> in, Step step);

  int level() const noexcept { return level_; }
  // XXH64 of every byte given since begin(): the frame's content checksum is made of it.
  const Xxh64& content_hash() const noexcept { return hash_; }

 private:
  std::unique_ptr<std::uint8_t[]> workspace_;
  void* context_ = nullptr;  // ZSTD_CCtx, inside workspace_
  std::unique_ptr<std::uint8_t[]> output_;
  std::size_t max_input_, output_bytes_;
  int level_;
  Xxh64 hash_;
};

}  // namespace pandarcap
