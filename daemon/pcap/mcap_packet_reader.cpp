#include "daemon/pcap/mcap_packet_reader.hpp"

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <limits>

#include "core/mcap/chunk_codec.hpp"
#include "core/mcap/mcap_parse.hpp"
#include "core/mcap/mcap_records.hpp"
#include "core/mcap/ros2_messages.hpp"

namespace pandarcap {
namespace {

std::string at_offset(std::uint64_t offset) {
  return " at offset " + std::to_string(offset);
}

}  // namespace

McapPacketReader::McapPacketReader(int fd, std::string path)
    : fd_(fd), path_(std::move(path)), offset_(mcap::kMagic.size()) {
  struct stat info {};
  if (::fstat(fd_, &info) == 0) size_ = static_cast<std::uint64_t>(info.st_size);
}

McapPacketReader::~McapPacketReader() {
  ::close(fd_);
}

CaptureStatus McapPacketReader::fail(CaptureStatus status, const std::string& what) {
  error_ = path_ + ": " + what;
  return status;
}

bool McapPacketReader::read_at(std::uint64_t offset, std::uint8_t* out, std::size_t n) {
  std::size_t done = 0;
  while (done < n) {
    const ssize_t got = ::pread(fd_, out + done, n - done, static_cast<off_t>(offset + done));
    if (got < 0 && errno == EINTR) continue;
    if (got < 0) {
      error_ = path_ + ": cannot read: " + std::strerror(errno);
      return false;
    }
    if (got == 0) {
      error_ = path_ + ": the file shrank while being read";
      return false;
    }
    done += static_cast<std::size_t>(got);
  }
  return true;
}

McapPacketReader::Handled McapPacketReader::load_chunk(std::span<const std::uint8_t> content,
                                                       std::uint64_t offset) {
  const auto chunk = mcap::parse_chunk(content);
  if (!chunk) {
    fail(CaptureStatus::kError, "the chunk" + at_offset(offset) + " does not parse");
    return Handled::kFailed;
  }
  if (!mcap::parse_compression_name(chunk->compression)) {
    fail(CaptureStatus::kError, "the chunk" + at_offset(offset) + " is compressed with '" +
                                    std::string(chunk->compression) +
                                    "', which is not read (zstd, lz4 or none)");
    return Handled::kFailed;
  }
  if (chunk->uncompressed_size > kMaxChunkBytes) {
    fail(CaptureStatus::kError,
         "the chunk" + at_offset(offset) + " claims " + std::to_string(chunk->uncompressed_size) +
             " bytes uncompressed, more than the " + std::to_string(kMaxChunkBytes >> 20) +
             " MiB a chunk may hold (a damaged file)");
    return Handled::kFailed;
  }
  // The zstd or LZ4 frame must state the same size (checked before the buffer is made that large).
  if (mcap::stored_content_size(chunk->compression, chunk->records) != chunk->uncompressed_size) {
    fail(CaptureStatus::kError,
         "the chunk" + at_offset(offset) + " does not hold the size it claims (a damaged file)");
    return Handled::kFailed;
  }
  if (chunk->uncompressed_size > chunk_capacity_) {
    // Not zero-filled: only what decompression writes is ever touched.
    chunk_.reset(new std::uint8_t[chunk->uncompressed_size]);
    chunk_capacity_ = chunk->uncompressed_size;
  }
  const std::span<std::uint8_t> records(chunk_.get(), chunk->uncompressed_size);
  if (!mcap::decompress_chunk(chunk->compression, chunk->records, records)) {
    fail(CaptureStatus::kError, "the chunk" + at_offset(offset) + " does not decompress");
    return Handled::kFailed;
  }
  if (chunk->uncompressed_crc != 0 && mcap::crc32(records) != chunk->uncompressed_crc) {
    fail(CaptureStatus::kError, "the chunk" + at_offset(offset) + " fails its CRC");
    return Handled::kFailed;
  }
  chunk_size_ = chunk->uncompressed_size;
  chunk_pos_ = 0;
  chunk_offset_ = offset;
  in_chunk_ = true;
  return Handled::kNone;
}

McapPacketReader::Handled McapPacketReader::handle(std::uint8_t op,
                                                   std::span<const std::uint8_t> content,
                                                   std::uint64_t offset, CaptureRecord& out,
                                                   CaptureStats& stats) {
  switch (static_cast<mcap::Op>(op)) {
    case mcap::Op::kSchema: {
      const auto schema = mcap::parse_schema(content);
      if (!schema) {
        fail(CaptureStatus::kError, "the schema" + at_offset(offset) + " does not parse");
        return Handled::kFailed;
      }
      packet_schemas_[schema->id] = schema->name == mcap::kPandarPacketName;
      return Handled::kNone;
    }
    case mcap::Op::kChannel: {
      // Parsed here rather than by mcap::parse_channel, which takes pandarcap's own ids only.
      mcap::ByteReader r(content);
      const std::uint16_t id = r.u16();
      const std::uint16_t schema = r.u16();
      r.string();  // topic
      const std::string_view encoding = r.string();
      r.bytes(r.u32());  // metadata
      if (r.failed() || r.remaining() != 0) {
        fail(CaptureStatus::kError, "the channel" + at_offset(offset) + " does not parse");
        return Handled::kFailed;
      }
      packet_channels_[id] = packet_schemas_[schema] && encoding == "cdr";
      return Handled::kNone;
    }
    case mcap::Op::kMessage: {
      const auto message = mcap::parse_message(content);
      if (!message) {
        fail(CaptureStatus::kError, "the message" + at_offset(offset) + " does not parse");
        return Handled::kFailed;
      }
      if (!packet_channels_[message->channel]) return Handled::kNone;
      ++stats.records;
      if (channel_ && *channel_ != message->channel) {
        ++stats.port_filtered;  // another sensor's packets
        return Handled::kNone;
      }
      channel_ = message->channel;
      const auto packet = mcap::parse_pandar_packet(message->data);
      if (!packet) {
        ++stats.malformed;
        return Handled::kNone;
      }
      CaptureRecord record;
      record.payload = packet->data;
      record.udp_payload_length = static_cast<std::uint32_t>(packet->data.size());
      constexpr auto kMaxTime =
          static_cast<std::uint64_t>(std::numeric_limits<std::int64_t>::max());
      record.timestamp_ns = static_cast<std::int64_t>(std::min(message->log_time, kMaxTime));
      ++stats.udp_datagrams;
      out = record;
      return Handled::kRecord;
    }
    default:
      return Handled::kNone;  // metadata, attachments, indexes: nothing to replay
  }
}

CaptureStatus McapPacketReader::next(CaptureRecord& out, CaptureStats& stats) {
  for (;;) {
    if (in_chunk_) {
      if (chunk_pos_ == chunk_size_) {
        in_chunk_ = false;
        continue;
      }
      const std::span<const std::uint8_t> rest(chunk_.get() + chunk_pos_, chunk_size_ - chunk_pos_);
      const auto record = mcap::record_at(rest);
      if (!record) {
        return fail(CaptureStatus::kError, "a record inside the chunk" + at_offset(chunk_offset_) +
                                               " runs past its end (a damaged file)");
      }
      chunk_pos_ += mcap::kRecordPrefixBytes + record->content.size();
      if (record->op == mcap::Op::kChunk) {
        return fail(CaptureStatus::kError,
                    "a chunk inside the chunk" + at_offset(chunk_offset_) + " (a damaged file)");
      }
      switch (handle(static_cast<std::uint8_t>(record->op), record->content, chunk_offset_, out,
                     stats)) {
        case Handled::kRecord:
          return CaptureStatus::kRecord;
        case Handled::kFailed:
          return CaptureStatus::kError;
        case Handled::kNone:
          continue;
      }
    }

    if (offset_ == size_) {
      return fail(CaptureStatus::kTruncated,
                  "the file ends before its data end record (cut off while recording)");
    }
    std::uint8_t prefix[mcap::kRecordPrefixBytes];
    if (size_ - offset_ < sizeof prefix) {
      return fail(CaptureStatus::kTruncated, "the file ends inside a record header" +
                                                 at_offset(offset_) + " (cut off while recording)");
    }
    if (!read_at(offset_, prefix, sizeof prefix)) return CaptureStatus::kError;
    mcap::ByteReader r(std::span<const std::uint8_t>(prefix, sizeof prefix));
    const std::uint8_t op = r.u8();
    const std::uint64_t length = r.u64();
    const std::uint64_t offset = offset_;
    if (length > size_ - offset_ - sizeof prefix) {
      return fail(CaptureStatus::kTruncated, "the file ends inside the record" + at_offset(offset) +
                                                 " (cut off while recording)");
    }
    offset_ += sizeof prefix + length;
    const auto kind = static_cast<mcap::Op>(op);
    if (kind == mcap::Op::kDataEnd || kind == mcap::Op::kFooter) return CaptureStatus::kEnd;
    if (kind != mcap::Op::kChunk && kind != mcap::Op::kMessage && kind != mcap::Op::kSchema &&
        kind != mcap::Op::kChannel) {
      continue;  // not read: skipped by its length
    }
    if (length > kMaxMcapRecordBytes) {
      return fail(CaptureStatus::kError, "the record" + at_offset(offset) + " claims " +
                                             std::to_string(length) + " bytes (a damaged file)");
    }
    record_.resize(length);
    if (!read_at(offset + sizeof prefix, record_.data(), record_.size())) {
      return CaptureStatus::kError;
    }
    const Handled handled = kind == mcap::Op::kChunk ? load_chunk(record_, offset)
                                                     : handle(op, record_, offset, out, stats);
    if (handled == Handled::kRecord) return CaptureStatus::kRecord;
    if (handled == Handled::kFailed) return CaptureStatus::kError;
  }
}

}  // namespace pandarcap
