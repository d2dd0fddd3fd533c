#include "daemon/mcap/mcap_recovery.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <optional>
#include <vector>

#include "core/mcap/chunk_codec.hpp"
#include "core/mcap/mcap_parse.hpp"
#include "core/mcap/mcap_records.hpp"
#include "daemon/io/errors.hpp"
#include "daemon/io/file_output.hpp"
#include "daemon/io/unique_fd.hpp"

namespace pandarcap {
namespace {

// No record pandarcap writes comes near this (chunks are a few MB); a larger length is damage.
constexpr std::uint64_t kMaxRecordBytes = 1ull << 30;

class Scanner {
 public:
  Scanner(int fd, std::uint64_t size, const std::string& path)
      : fd_(fd), size_(size), path_(path) {}

  // The record at `at`, read whole (prefix included), or nothing when the file ends inside it.
  std::optional<mcap::RecordView> read(std::uint64_t at) {
    std::array<std::uint8_t, mcap::kRecordPrefixBytes> prefix{};
    if (!pread_all(prefix.data(), prefix.size(), at)) return std::nullopt;
    mcap::ByteReader r(prefix);
    r.u8();
    const std::uint64_t length = r.u64();
    if (length > kMaxRecordBytes || at + mcap::kRecordPrefixBytes + length > size_) {
      return std::nullopt;
    }
    buffer_.resize(mcap::kRecordPrefixBytes + length);
    if (!pread_all(buffer_.data(), buffer_.size(), at)) return std::nullopt;
    return mcap::record_at(buffer_);
  }

 private:
  bool pread_all(std::uint8_t* out, std::size_t n, std::uint64_t at) {
    if (at + n > size_) return false;
    std::size_t done = 0;
    while (done < n) {
      const ssize_t got = ::pread(fd_, out + done, n - done, static_cast<off_t>(at + done));
      if (got < 0 && errno == EINTR) continue;
      if (got < 0) io::throw_errno("cannot read", path_);
      if (got == 0) return false;
      done += static_cast<std::size_t>(got);
    }
    return true;
  }

  int fd_;
  std::uint64_t size_;
  const std::string& path_;
  std::vector<std::uint8_t> buffer_;
};

bool is_pandarcap_header(const mcap::RecordView& record) {
  if (record.op != mcap::Op::kHeader) return false;
  mcap::ByteReader r(record.content);
  r.string();  // profile
  const std::string_view library = r.string();
  return !r.failed() && library.starts_with("pandarcap");
}

// A chunk's messages, checked: per channel, how many and their times. Nothing when the chunk is
// damaged.
struct ChunkContents {
  std::array<std::uint64_t, mcap::kMaxChannels + 1> count{};
  std::vector<std::uint64_t> log_times[mcap::kMaxChannels + 1];
};
// pandarcap's chunks compress 2x or so (points), 10x at most (health JSON): a chunk whose
// stated size is far beyond its stored bytes is damage, and is refused before any allocation.
constexpr std::uint64_t kMaxCompressionRatio = 64;

std::optional<ChunkContents> read_chunk(const mcap::ChunkView& chunk) {
  if (chunk.uncompressed_size > kMaxRecordBytes ||
      chunk.uncompressed_size > kMaxCompressionRatio * chunk.records.size() + 65536 ||
      mcap::stored_content_size(chunk.compression, chunk.records) != chunk.uncompressed_size) {
    return std::nullopt;
  }
  std::vector<std::uint8_t> records(chunk.uncompressed_size);
  if (!mcap::decompress_chunk(chunk.compression, chunk.records, records)) return std::nullopt;
  if (chunk.uncompressed_crc != 0 && mcap::crc32(records) != chunk.uncompressed_crc) {
    return std::nullopt;
  }
  ChunkContents contents;
  std::span<const std::uint8_t> rest(records);
  while (!rest.empty()) {
    const auto record = mcap::record_at(rest);
    if (!record) return std::nullopt;
    if (record->op == mcap::Op::kMessage) {
      const auto message = mcap::parse_message(record->content);
      if (!message || message->channel == 0 || message->channel > mcap::kMaxChannels) {
        return std::nullopt;
      }
      ++contents.count[message->channel];
      contents.log_times[message->channel].push_back(message->log_time);
    }
    rest = rest.subspan(mcap::kRecordPrefixBytes + record->content.size());
  }
  return contents;
}

}  // namespace

McapRecovery finish_interrupted_mcap(const std::string& path) {
  auto [fd, size] = open_leftover(path, O_RDWR);

  McapRecovery result;
  std::array<std::uint8_t, mcap::kMagic.size()> magic{};
  const ssize_t got = ::pread(fd.get(), magic.data(), magic.size(), 0);
  if (got < 0) io::throw_errno("cannot read", path);
  const auto have = static_cast<std::size_t>(got);
  if (!std::equal(magic.begin(), magic.begin() + static_cast<std::ptrdiff_t>(have),
                  mcap::kMagic.begin())) {
    return result;  // not an MCAP file
  }
  Scanner scan(fd.get(), size, path);
  std::uint64_t at = mcap::kMagic.size();
  const auto header = have == magic.size() ? scan.read(at) : std::nullopt;
  if (!header) {
    // Cut before its header was whole: ours (the name and the magic say so), with nothing in it.
    result.ours = true;
    result.cut_bytes = size;
    return result;
  }
  if (!is_pandarcap_header(*header)) return result;
  result.ours = true;
  at += mcap::kRecordPrefixBytes + header->content.size();

  mcap::Summary summary;
  std::uint64_t kept = at;
  while (true) {
    const auto record = scan.read(at);
    if (!record) break;
    const std::uint64_t length = mcap::kRecordPrefixBytes + record->content.size();
    bool whole = true;
    switch (record->op) {
      case mcap::Op::kSchema:
        if (const auto s = mcap::parse_schema(record->content)) {
          summary.schemas.push_back(*s);
        } else {
          whole = false;
        }
        break;
      case mcap::Op::kChannel:
        if (const auto c = mcap::parse_channel(record->content)) {
          summary.channels.push_back(*c);
        } else {
          whole = false;
        }
        break;
      case mcap::Op::kMetadata:
        if (const auto name = mcap::parse_metadata_name(record->content)) {
          summary.metadata.push_back({at, length, std::string(*name)});
        } else {
          whole = false;
        }
        break;
      case mcap::Op::kAttachment:
        if (auto a = mcap::parse_attachment(record->content)) {
          a->offset = at;
          a->length = length;
          summary.attachments.push_back(*a);
        } else {
          whole = false;
        }
        break;
      case mcap::Op::kChunk: {
        const auto chunk = mcap::parse_chunk(record->content);
        auto contents = chunk ? read_chunk(*chunk) : std::nullopt;
        if (!contents) {
          whole = false;
          break;
        }
        mcap::ChunkInfo info;
        info.message_start_time = chunk->message_start_time;
        info.message_end_time = chunk->message_end_time;
        info.chunk_start_offset = at;
        info.chunk_length = length;
        // A chunk that decompressed has a compression pandarcap reads: the name, as stored.
        info.compression = mcap::compression_name(mcap::parse_compression_name(chunk->compression)
                                                      .value_or(mcap::ChunkCompression::kNone));
        info.compressed_size = chunk->records.size();
        info.uncompressed_size = chunk->uncompressed_size;
        // Its indexes follow: one per channel with messages in the chunk, each whole.
        std::uint64_t index_at = at + length;
        std::size_t expected = 0;
        for (std::size_t c = 1; c <= mcap::kMaxChannels; ++c)
          expected += contents->count[c] != 0;
        std::size_t found = 0;
        while (found < expected) {
          const auto index = scan.read(index_at);
          if (!index || index->op != mcap::Op::kMessageIndex) break;
          const auto channel = mcap::parse_message_index_channel(index->content);
          if (!channel || *channel == 0 || *channel > mcap::kMaxChannels ||
              contents->count[*channel] == 0 || info.message_index_offset[*channel - 1] != 0) {
            break;
          }
          info.message_index_offset[*channel - 1] = index_at;
          index_at += mcap::kRecordPrefixBytes + index->content.size();
          ++found;
        }
        if (found != expected) {
          whole = false;
          break;
        }
        info.message_index_length = index_at - (at + length);
        summary.chunks.push_back(info);
        for (std::uint16_t c = 1; c <= mcap::kMaxChannels; ++c) {
          for (const std::uint64_t t : contents->log_times[c])
            summary.count_message(c, t);
        }
        at = index_at;
        kept = at;
        continue;
      }
      case mcap::Op::kPadding:
        break;  // whole (scan.read gave all of it): the writer's block alignment, kept
      default:
        whole = false;  // DataEnd (an old tail, rewritten) or anything unexpected: cut here
        break;
    }
    if (!whole) break;
    at += length;
    kept = at;
  }

  result.messages = summary.message_count;
  result.kept_bytes = kept;
  result.cut_bytes = size - kept;
  if (result.messages == 0) return result;
  if (::ftruncate(fd.get(), static_cast<off_t>(kept)) != 0)
    io::throw_errno("cannot truncate", path);
  std::vector<std::uint8_t> tail;
  mcap::ByteWriter w(tail);
  mcap::write_tail(w, kept, summary);
  // Through the test seam (io::file_syscalls), as the daemon's other writes: a disk that stays
  // full fails this one too.
  if (::lseek(fd.get(), static_cast<off_t>(kept), SEEK_SET) < 0) {
    io::throw_errno("cannot seek", path);
  }
  std::uint64_t written = 0;
  if (const int error = write_fully(fd.get(), tail, written)) {
    io::throw_error(error, "cannot write", path);
  }
  if (::fsync(fd.get()) != 0) io::throw_errno("cannot sync", path);
  return result;
}

}  // namespace pandarcap
