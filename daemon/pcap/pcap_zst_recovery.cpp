// Finishing a compressed recording a killed run left (NAME.pcap.zst.part): see pcap_recovery.hpp.
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zstd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstring>
#include <memory>
#include <system_error>
#include <vector>

#include "daemon/io/errors.hpp"
#include "daemon/io/file_output.hpp"
#include "daemon/io/unique_fd.hpp"
#include "daemon/pcap/pcap_recovery.hpp"
#include "daemon/pcap/pcap_writer.hpp"
#include "daemon/pcap/xxh64.hpp"
#include "daemon/pcap/zstd_write_stream.hpp"

namespace pandarcap {
namespace {

// zstd frames of ours use a window far below this (level 1: 512 KiB); a file asking for more is
// not ours, and would only make the start-up allocate what the file says.
constexpr int kMaxWindowLog = 24;
constexpr std::size_t kReadBytes = 64 * 1024;
struct DctxFree {
  void operator()(ZSTD_DCtx* context) const noexcept { ZSTD_freeDCtx(context); }
};

// The frame header's length from its first bytes (RFC 8878 3.1.1.1), or 0 when they are not a
// zstd frame's (or not all there).
std::size_t frame_header_bytes(const std::uint8_t* p, std::size_t size, bool& checksum) noexcept {
  if (size < 5 || std::memcmp(p, kZstdMagic.data(), kZstdMagic.size()) != 0) return 0;
  const std::uint8_t descriptor = p[4];
  const bool single_segment = (descriptor & 0x20) != 0;
  checksum = (descriptor & 0x04) != 0;
  constexpr std::size_t kDictionaryIdBytes[] = {0, 1, 2, 4};
  constexpr std::size_t kContentSizeBytes[] = {0, 2, 4, 8};
  std::size_t content_size = kContentSizeBytes[descriptor >> 6];
  if (content_size == 0 && single_segment) content_size = 1;
  const std::size_t bytes =
      5 + (single_segment ? 0 : 1) + kDictionaryIdBytes[descriptor & 0x03] + content_size;
  return bytes <= size ? bytes : 0;
}

// The pcap stream decompressed block by block, its whole records followed as they come: where the
// last block that ends on a whole record ends, in the file and in the stream, and the stream's
// hash up to there.
class BlockWalk {
 public:
  BlockWalk(int fd, const std::string& path, std::uint64_t size)
      : fd_(fd), path_(path), size_(size) {
    context_.reset(ZSTD_createDCtx());
    if (!context_) throw std::bad_alloc();
    ZSTD_DCtx_setParameter(context_.get(), ZSTD_d_windowLogMax, kMaxWindowLog);
  }

  // The frame header; false when the file does not begin as one.
  bool start(bool& checksum) {
    std::array<std::uint8_t, 18> head{};  // the longest frame header
    const std::size_t got = read(0, head.data(), std::min<std::uint64_t>(size_, head.size()));
    header_bytes_ = frame_header_bytes(head.data(), got, checksum);
    if (header_bytes_ == 0) return false;
    return feed(0, header_bytes_);
  }

  // The next whole block, decompressed; false at the end of what the file holds whole (a cut
  // block, the last block, garbage).
  bool next_block() {
    const std::uint64_t at = header_bytes_ + compressed_;
    std::uint8_t h[3];
    if (at + 3 > size_ || read(at, h, 3) != 3) return false;
    const std::uint32_t header = h[0] | (h[1] << 8) | (static_cast<std::uint32_t>(h[2]) << 16);
    if ((header & 1) != 0) {  // the last block: the frame was finished already
      last_ = true;
      return false;
    }
    const std::uint32_t type = (header >> 1) & 3, size = header >> 3;
    const std::uint64_t body = type == 1 ? 1 : size;       // RLE: one byte repeated
    if (type == 3 || at + 3 + body > size_) return false;  // reserved, or cut short
    if (!feed(at, 3 + body)) return false;
    compressed_ += 3 + body;
    return true;
  }

  std::vector<std::uint8_t>& stream() noexcept { return stream_; }
  // The file's offset after the frame header and the blocks walked so far.
  std::uint64_t offset() const noexcept { return header_bytes_ + compressed_; }
  bool found_last_block() const noexcept { return last_; }
  Xxh64& hash() noexcept { return hash_; }

 private:
  std::size_t read(std::uint64_t at, std::uint8_t* to, std::size_t n) {
    std::size_t done = 0;
    while (done < n) {
      const ssize_t got = ::pread(fd_, to + done, n - done, static_cast<off_t>(at + done));
      if (got < 0 && errno == EINTR) continue;
      if (got < 0) io::throw_errno("cannot read", path_);
      if (got == 0) break;
      done += static_cast<std::size_t>(got);
    }
    return done;
  }

  // Decompresses the file's bytes [at, at + n) into stream_; false on corrupt data.
  bool feed(std::uint64_t at, std::uint64_t n) {
    std::array<std::uint8_t, 64 * 1024> in{};
    std::array<std::uint8_t, 128 * 1024> out{};
    while (n > 0) {
      const std::size_t take = static_cast<std::size_t>(std::min<std::uint64_t>(n, in.size()));
      if (read(at, in.data(), take) != take) return false;
      ZSTD_inBuffer input{in.data(), take, 0};
      // Until the input is used and zstd holds nothing back for a full output buffer.
      while (true) {
        ZSTD_outBuffer output{out.data(), out.size(), 0};
        const std::size_t r = ZSTD_decompressStream(context_.get(), &output, &input);
        if (ZSTD_isError(r)) return false;
        stream_.insert(stream_.end(), out.data(), out.data() + output.pos);
        hash_.update({out.data(), output.pos});
        if (input.pos == input.size && output.pos < output.size) break;
      }
      at += take;
      n -= take;
    }
    return true;
  }

  int fd_;
  const std::string& path_;
  std::uint64_t size_;
  std::unique_ptr<ZSTD_DCtx, DctxFree> context_;
  std::size_t header_bytes_ = 0;
  std::uint64_t compressed_ = 0;  // the whole blocks walked, with their headers
  std::vector<std::uint8_t> stream_;
  Xxh64 hash_;
  bool last_ = false;
};

// The file's bytes, decompressed as far as they go: a cut frame or corrupt data ends them (as
// the end of the file does), never with an error: what decompressed before it is what counts.
class Decompressed {
 public:
  Decompressed(int fd, const std::string& path) : fd_(fd), path_(path), in_(kReadBytes) {
    context_.reset(ZSTD_createDCtx());
    if (!context_) throw std::bad_alloc();
    ZSTD_DCtx_setParameter(context_.get(), ZSTD_d_windowLogMax, kMaxWindowLog);
  }
  // Appends the next decompressed bytes to `out`; false when nothing more comes.
  bool more(std::vector<std::uint8_t>& out) {
    std::array<std::uint8_t, 128 * 1024> chunk{};
    while (!ended_) {
      if (input_.pos == input_.size && !end_of_file_) {
        const ssize_t got = ::read(fd_, in_.data(), in_.size());
        if (got < 0) {
          if (errno == EINTR) continue;
          io::throw_errno("cannot read", path_);
        }
        if (got == 0) end_of_file_ = true;
        input_ = {in_.data(), static_cast<std::size_t>(got), 0};
      }
      // At the end of the file too: a block decompressed into a full output is held back by
      // zstd until it is asked again.
      ZSTD_outBuffer output{chunk.data(), chunk.size(), 0};
      const std::size_t r = ZSTD_decompressStream(context_.get(), &output, &input_);
      if (ZSTD_isError(r)) ended_ = true;  // corrupt or not zstd at all: the good part ends
      if (output.pos > 0) {
        out.insert(out.end(), chunk.data(), chunk.data() + output.pos);
        return true;
      }
      if (end_of_file_ && input_.pos == input_.size) ended_ = true;  // nothing held back
    }
    return false;
  }

 private:
  int fd_;
  const std::string& path_;
  std::unique_ptr<ZSTD_DCtx, DctxFree> context_;
  std::vector<std::uint8_t> in_;
  ZSTD_inBuffer input_{nullptr, 0, 0};
  bool end_of_file_ = false;
  bool ended_ = false;
};

}  // namespace

// In place: see finish_interrupted_pcap_zst (the way taken when the disk has no room for a copy).
static PcapRecovery finish_in_place(const std::string& path) {
  const auto [file, size] = open_leftover(path, O_RDWR);
  PcapRecovery result;
  result.kept_bytes = size;
  BlockWalk walk(file.get(), path, size);
  bool checksum = false;
  if (!walk.start(checksum)) {
    // Not even a frame header: ours, with no record, if it begins as a zstd frame does.
    std::array<std::uint8_t, kZstdMagic.size()> start{};
    const ssize_t n = ::pread(file.get(), start.data(), start.size(), 0);
    result.ours = n >= 0 && static_cast<std::uint64_t>(n) == std::min<std::uint64_t>(size, 4) &&
                  std::memcmp(start.data(), kZstdMagic.data(), static_cast<std::size_t>(n)) == 0;
    return result;
  }
  // Block by block, in place: the frame is cut after the last block that ends on a whole record
  // and ended there with an empty last block (and its content checksum, for the records before
  // it). No copy of the file is made: a disk short of space can still finish a large one.
  const auto header = pcap_global_header();
  std::vector<std::uint8_t>& stream = walk.stream();
  std::uint64_t good_offset = 0, good_stream = 0, good_records = 0, records = 0;
  Xxh64 good_hash;
  std::size_t at = 0;    // the next record's start in the stream
  bool whole = true;     // every record so far was one of ours
  bool checked = false;  // the global header was seen
  while (whole && walk.next_block()) {
    if (!checked && stream.size() >= header.size()) {
      result.ours = std::memcmp(stream.data(), header.data(), header.size()) == 0;
      if (!result.ours) return result;
      checked = true;
      at = header.size();
    }
    if (!checked) continue;
    while (stream.size() - at >= kPcapRecordHeaderBytes) {
      const std::optional<std::uint32_t> captured = pcap_record_captured_bytes(stream.data() + at);
      if (!captured) {  // not a header of ours: the good part ends before it
        whole = false;
        break;
      }
      const std::size_t record = kPcapRecordHeaderBytes + *captured;
      if (stream.size() - at < record) break;  // the rest is in the next block (or never came)
      at += record;
      ++records;
    }
    if (whole && at == stream.size()) {  // this block ends on a whole record
      good_offset = walk.offset();
      good_stream = stream.size();
      good_records = records;
      good_hash = walk.hash();
    }
  }
  if (!checked) {
    result.ours =
        std::memcmp(stream.data(), header.data(), std::min(stream.size(), header.size())) == 0;
    return result;
  }
  if (walk.found_last_block() && whole && at == stream.size()) {
    // Finished already (killed between its end and its rename): kept as it is.
    result.records = records;
    return result;
  }
  result.records = good_records;
  result.cut_bytes = stream.size() - good_stream;  // of the pcap stream: a cut record, garbage
  if (good_records == 0) return result;
  // Cut after the good block, then the empty last block and the checksum of what it holds.
  if (::ftruncate(file.get(), static_cast<off_t>(good_offset)) != 0)
    io::throw_errno("cannot truncate", path);
  std::vector<std::uint8_t> end(kZstdEmptyLastBlock.begin(), kZstdEmptyLastBlock.end());
  if (checksum) {
    const auto sum = zstd_content_checksum(good_hash);
    end.insert(end.end(), sum.begin(), sum.end());
  }
  if (::pwrite(file.get(), end.data(), end.size(), static_cast<off_t>(good_offset)) !=
      static_cast<ssize_t>(end.size())) {
    io::throw_errno("cannot write", path);
  }
  result.kept_bytes = good_offset + end.size();
  return result;
}

PcapRecovery finish_interrupted_pcap_zst(const std::string& path) {
  const auto [file, size] = open_leftover(path, O_RDONLY);
  PcapRecovery result;
  result.kept_bytes = size;

  std::vector<std::uint8_t> stream;  // decompressed, not yet copied out
  Decompressed decompressed(file.get(), path);
  while (stream.size() < kPcapGlobalHeaderBytes && decompressed.more(stream)) {
  }
  // Ours: the stream begins with PcapWriter's global header, or with the start of it (killed
  // before the header was flushed: a file no longer than the zstd magic, or a header cut short).
  const auto header = pcap_global_header();
  const std::size_t present = std::min(stream.size(), header.size());
  if (stream.empty()) {
    // Nothing decompressed: ours, with no record, if it begins as a zstd frame does.
    std::array<std::uint8_t, kZstdMagic.size()> start{};
    const ssize_t n = ::pread(file.get(), start.data(), start.size(), 0);
    result.ours = n >= 0 && static_cast<std::uint64_t>(n) == std::min<std::uint64_t>(size, 4) &&
                  std::memcmp(start.data(), kZstdMagic.data(), static_cast<std::size_t>(n)) == 0;
    return result;
  }
  result.ours = std::memcmp(stream.data(), header.data(), present) == 0;
  if (!result.ours || present < header.size()) return result;

  // The whole records, compressed again into one finished frame beside the file, which then
  // replaces it: the cut frame cannot be ended where it stands (its last block may hold half a
  // record), and the rename keeps the .part intact until the finished file is complete.
  const std::string temporary = temporary_name(path).native();
  ZstdStreamCompressor compressor(kPcapBufferBytes, 1);
  OutputFile out(temporary, OutputFile::Mode::kCreate);
  try {
    out.write(compressor.compress(header, ZstdStreamCompressor::Step::kContinue));
    std::size_t at = header.size();
    bool good = true;
    do {
      while (good && stream.size() - at >= kPcapRecordHeaderBytes) {
        const std::optional<std::uint32_t> captured =
            pcap_record_captured_bytes(stream.data() + at);
        if (!captured) {  // not a header of ours: the good part ends here
          good = false;
          break;
        }
        const std::size_t record = kPcapRecordHeaderBytes + *captured;
        if (stream.size() - at < record) break;  // the rest is still to come (or never came)
        out.write(compressor.compress({stream.data() + at, record},
                                      ZstdStreamCompressor::Step::kContinue));
        at += record;
        ++result.records;
      }
      stream.erase(stream.begin(), stream.begin() + static_cast<std::ptrdiff_t>(at));
      at = 0;
    } while (good && decompressed.more(stream));
    if (result.records == 0) {
      out.close();
      std::filesystem::remove(temporary);
      return result;
    }
    out.write(compressor.compress({}, ZstdStreamCompressor::Step::kEnd));
    out.sync();  // whole on the disk before it replaces the .part (which is whole until then)
    out.close();
    rename_replacing(temporary, path);
    result.kept_bytes = out.size();
    result.cut_bytes = stream.size();  // of the pcap stream: the record cut short, or garbage
  } catch (const std::system_error& error) {
    std::error_code ignored;
    std::filesystem::remove(temporary, ignored);
    const int code = error.code().value();
    if (code != ENOSPC && code != EDQUOT && code != EFBIG) throw;
    // No room for the copy (a disk our own recordings fill, a power cut's): the frame is ended
    // where it stands instead, after its last block that ends on a whole record (the records
    // after it, at most those since the writer's last flush, are left out).
    return finish_in_place(path);
  } catch (...) {
    std::error_code ignored;
    std::filesystem::remove(temporary, ignored);
    throw;
  }
  return result;
}

}  // namespace pandarcap
