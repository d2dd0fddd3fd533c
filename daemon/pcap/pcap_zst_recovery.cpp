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
  } catch (...) {
    std::error_code ignored;
    std::filesystem::remove(temporary, ignored);
    throw;
  }
  return result;
}

}  // namespace pandarcap
