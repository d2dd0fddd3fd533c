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
  read_chunk_index();
}

// Footer (opcode, length 20, summary start, summary offset start, summary CRC) and the magic.
void McapPacketReader::read_chunk_index() {
  constexpr std::size_t kFooterRecordBytes = mcap::kRecordPrefixBytes + 20;
  constexpr std::size_t kFileTailBytes = kFooterRecordBytes + mcap::kMagic.size();
  if (size_ < mcap::kMagic.size() + kFileTailBytes) return;
  std::uint8_t tail[kFileTailBytes];
  const std::uint64_t footer_at = size_ - kFileTailBytes;
  if (!read_at(footer_at, tail, sizeof tail)) {
    error_.clear();
    return;
  }
  mcap::ByteReader r(std::span<const std::uint8_t>(tail, sizeof tail));
  const auto op = static_cast<mcap::Op>(r.u8());
  const std::uint64_t length = r.u64();
  const std::uint64_t summary_start = r.u64();
  r.u64();  // summary offset start
  const std::uint32_t summary_crc = r.u32();
  if (op != mcap::Op::kFooter || length != 20 ||
      !std::equal(mcap::kMagic.begin(), mcap::kMagic.end(), tail + kFooterRecordBytes)) {
    return;
  }
  has_footer_ = true;
  if (summary_start < mcap::kMagic.size() || summary_start >= footer_at ||
      footer_at - summary_start > kMaxMcapRecordBytes) {
    return;
  }
  // The CRC covers the summary and summary offset sections and the footer up to the CRC.
  std::vector<std::uint8_t> summary(footer_at + kFooterRecordBytes - 4 - summary_start);
  if (!read_at(summary_start, summary.data(), summary.size())) {
    error_.clear();
    return;
  }
  if (summary_crc != 0 && mcap::crc32(summary) != summary_crc) return;  // not to be trusted
  data_end_ = summary_start;
  std::span<const std::uint8_t> rest(summary.data(), footer_at - summary_start);
  while (const auto record = mcap::record_at(rest)) {
    rest = rest.subspan(mcap::kRecordPrefixBytes + record->content.size());
    if (record->op != mcap::Op::kChunkIndex) continue;
    mcap::ByteReader c(record->content);
    c.u64();  // message start time
    c.u64();  // message end time
    IndexedChunk chunk;
    chunk.start = c.u64();
    chunk.length = c.u64();
    c.bytes(c.u32());  // message index offsets
    chunk.message_index_length = c.u64();
    if (c.failed() || chunk.start < mcap::kMagic.size() || chunk.start >= summary_start ||
        chunk.length > summary_start - chunk.start) {
      chunks_.clear();  // an index that points outside the data is not used at all
      return;
    }
    chunks_.push_back(chunk);
  }
  std::sort(chunks_.begin(), chunks_.end(),
            [](const IndexedChunk& a, const IndexedChunk& b) { return a.start < b.start; });
}

std::uint64_t McapPacketReader::indexed_packets(std::size_t i) {
  const IndexedChunk& chunk = chunks_[i];
  const std::uint64_t at = chunk.start + chunk.length;
  if (chunk.message_index_length > kMaxMcapRecordBytes || at > size_ ||
      chunk.message_index_length > size_ - at) {
    return 0;
  }
  std::vector<std::uint8_t> indexes(chunk.message_index_length);
  if (!read_at(at, indexes.data(), indexes.size())) {
    error_.clear();
    return 0;
  }
  std::uint64_t packets = 0;
  std::span<const std::uint8_t> rest(indexes);
  while (const auto record = mcap::record_at(rest)) {
    rest = rest.subspan(mcap::kRecordPrefixBytes + record->content.size());
    if (record->op != mcap::Op::kMessageIndex) continue;
    mcap::ByteReader m(record->content);
    const std::uint16_t channel = m.u16();
    const std::uint32_t entries_bytes = m.u32();  // (log time, offset) pairs of 16 bytes
    if (!m.failed() && packet_channels_[channel] && (!channel_ || *channel_ == channel))
      packets += entries_bytes / 16;
  }
  return packets;
}

bool McapPacketReader::skip_past(std::uint64_t offset, bool chunk, const std::string& what,
                                 CaptureStats& stats) {
  std::size_t next = 0;
  while (next < chunks_.size() && chunks_[next].start <= offset)
    ++next;
  if (next == chunks_.size()) return false;
  if (chunk) {
    ++stats.chunks_skipped;
    // The damaged chunk is the indexed one it starts at, if any.
    if (next > 0 && chunks_[next - 1].start == offset)
      stats.packets_skipped += indexed_packets(next - 1);
  } else {
    ++stats.records_damaged;
  }
  if (first_damage_.empty()) first_damage_ = path_ + ": " + what;
  in_chunk_ = false;
  offset_ = chunks_[next].start;
  next_chunk_ = next;
  return true;
}

McapPacketReader::~McapPacketReader() {
  ::close(fd_);
}

std::optional<SensorModelId> McapPacketReader::named_model() const noexcept {
  for (const auto& [channel, model] : named_models_) {
    if (!channel_ || *channel_ == channel) return model;
  }
  return std::nullopt;
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
      mcap::ByteReader metadata(r.bytes(r.u32()));
      if (r.failed() || r.remaining() != 0) {
        fail(CaptureStatus::kError, "the channel" + at_offset(offset) + " does not parse");
        return Handled::kFailed;
      }
      packet_channels_[id] = packet_schemas_[schema] && encoding == "cdr";
      // The model its writer names (pandarcapd's sensor_model): a hint, the packets decide. A
      // damaged map or a name pandarcap does not know is no hint.
      while (packet_channels_[id] && !metadata.failed() && metadata.remaining() > 0) {
        const std::string_view key = metadata.string();
        const std::string_view value = metadata.string();
        if (metadata.failed() || key != "sensor_model") continue;
        // A handful of sensors at most: a file of endless Channel records grows nothing.
        const auto model = parse_sensor_model(value);
        if (model && named_models_.size() < kMaxNamedChannels)
          named_models_.emplace_back(id, *model);
      }
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
      std::string damage;
      if (!record) {
        damage = "a record inside the chunk" + at_offset(chunk_offset_) +
                 " runs past its end (a damaged file)";
      } else if (record->op == mcap::Op::kChunk) {
        damage = "a chunk inside the chunk" + at_offset(chunk_offset_) + " (a damaged file)";
      } else {
        chunk_pos_ += mcap::kRecordPrefixBytes + record->content.size();
        switch (handle(static_cast<std::uint8_t>(record->op), record->content, chunk_offset_, out,
                       stats)) {
          case Handled::kRecord:
            return CaptureStatus::kRecord;
          case Handled::kFailed:
            damage = error_.substr(path_.size() + 2);
            break;
          case Handled::kNone:
            continue;
        }
      }
      // The rest of this chunk is lost (its packets before the damage were yielded).
      if (skip_past(chunk_offset_, true, damage, stats)) {
        error_.clear();
        continue;
      }
      return fail(CaptureStatus::kError, damage);
    }

    // A record before this one claimed a length that ran over an indexed chunk's start: its
    // length is damaged. Reading resumes at that chunk, which loses nothing of it.
    if (next_chunk_ < chunks_.size() && chunks_[next_chunk_].start < offset_) {
      ++stats.records_damaged;
      if (first_damage_.empty()) {
        first_damage_ = path_ + ": a record before offset " + std::to_string(offset_) +
                        " has a damaged length (it runs over the chunk" +
                        at_offset(chunks_[next_chunk_].start) + ")";
      }
      offset_ = chunks_[next_chunk_].start;
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
    std::uint64_t length = r.u64();
    const std::uint64_t offset = offset_;
    const auto kind = static_cast<mcap::Op>(op);
    const bool indexed_chunk_here =
        next_chunk_ < chunks_.size() && chunks_[next_chunk_].start == offset;
    if (indexed_chunk_here) {
      // The index knows the chunk's length: a different one in the record is damage, read over
      // with the index's (the chunk's own CRC then says whether its content is whole).
      const std::uint64_t indexed = chunks_[next_chunk_].length - sizeof prefix;
      if (kind == mcap::Op::kChunk && length != indexed) {
        ++stats.records_damaged;
        if (first_damage_.empty()) {
          first_damage_ = path_ + ": the chunk" + at_offset(offset) + " claims " +
                          std::to_string(length) + " bytes, its index " + std::to_string(indexed) +
                          ": a damaged length (read with the index's)";
        }
        length = indexed;
      }
      ++next_chunk_;
    }
    // Damage at the top level: an opcode MCAP does not have (0, 0x10-0x7F), a chunk where the
    // index has none or none where it has one, or a length past the end of a finished file.
    std::string damage;
    if (op == 0 || (op > static_cast<std::uint8_t>(mcap::Op::kDataEnd) && op < 0x80)) {
      damage = "the record" + at_offset(offset) + " has opcode " + std::to_string(op) +
               ", which MCAP does not have (a damaged file)";
    } else if (!chunks_.empty() && (kind == mcap::Op::kChunk) != indexed_chunk_here) {
      damage =
          indexed_chunk_here
              ? "the chunk" + at_offset(offset) + " the index lists is not there (a damaged file)"
              : "a chunk" + at_offset(offset) + " that the index does not list (a damaged file)";
    } else if (data_end_ > 0 && offset < data_end_ && length > data_end_ - offset - sizeof prefix) {
      damage = "the record" + at_offset(offset) + " claims " + std::to_string(length) +
               " bytes, past the data section's end (at " + std::to_string(data_end_) +
               ", the summary's start): a damaged length, not a file cut off";
    } else if (length > size_ - offset_ - sizeof prefix && has_footer_) {
      damage = "the record" + at_offset(offset) + " claims " + std::to_string(length) +
               " bytes, past the end of the file, which has its footer: a damaged length, not "
               "a file cut off";
    } else if (length > size_ - offset_ - sizeof prefix) {
      return fail(CaptureStatus::kTruncated, "the file ends inside the record" + at_offset(offset) +
                                                 " (cut off while recording)");
    } else if (length > kMaxMcapRecordBytes) {
      damage = "the record" + at_offset(offset) + " claims " + std::to_string(length) +
               " bytes (a damaged file)";
    }
    if (!damage.empty()) {
      if (skip_past(offset, indexed_chunk_here, damage, stats)) continue;
      return fail(CaptureStatus::kError, damage);
    }
    offset_ += sizeof prefix + length;
    if (kind == mcap::Op::kDataEnd || kind == mcap::Op::kFooter) return CaptureStatus::kEnd;
    if (kind != mcap::Op::kChunk && kind != mcap::Op::kMessage && kind != mcap::Op::kSchema &&
        kind != mcap::Op::kChannel) {
      continue;  // not read: skipped by its length
    }
    record_.resize(length);
    if (!read_at(offset + sizeof prefix, record_.data(), record_.size())) {
      return CaptureStatus::kError;
    }
    const Handled handled = kind == mcap::Op::kChunk ? load_chunk(record_, offset)
                                                     : handle(op, record_, offset, out, stats);
    if (handled == Handled::kRecord) return CaptureStatus::kRecord;
    if (handled == Handled::kFailed) {
      if (skip_past(offset, kind == mcap::Op::kChunk, error_.substr(path_.size() + 2), stats)) {
        error_.clear();
        continue;
      }
      return CaptureStatus::kError;
    }
  }
}

}  // namespace pandarcap
