#include "core/mcap/mcap_records.hpp"

#include <zlib.h>

#include <algorithm>
#include <cstring>

namespace pandarcap::mcap {

std::size_t ByteWriter::begin_record(Op op) {
  u8(static_cast<std::uint8_t>(op));
  const std::size_t handle = out_.size();
  u64(0);
  return handle;
}

void ByteWriter::end_record(std::size_t handle) {
  patch_u64(handle, out_.size() - handle - 8);
}

std::size_t ByteWriter::begin_u32_length() {
  const std::size_t handle = out_.size();
  u32(0);
  return handle;
}

void ByteWriter::end_u32_length(std::size_t handle) {
  const auto n = static_cast<std::uint32_t>(out_.size() - handle - 4);
  for (int i = 0; i < 4; ++i)
    out_[handle + i] = static_cast<std::uint8_t>(n >> (8 * i));
}

void ByteWriter::patch_u64(std::size_t at, std::uint64_t v) noexcept {
  for (int i = 0; i < 8; ++i)
    out_[at + i] = static_cast<std::uint8_t>(v >> (8 * i));
}

std::uint64_t ByteReader::little(int n) noexcept {
  if (failed_ || remaining() < static_cast<std::size_t>(n)) {
    failed_ = true;
    return 0;
  }
  std::uint64_t v = 0;
  for (int i = 0; i < n; ++i)
    v |= std::uint64_t{in_[at_ + i]} << (8 * i);
  at_ += n;
  return v;
}

std::span<const std::uint8_t> ByteReader::bytes(std::uint64_t n) noexcept {
  if (failed_ || remaining() < n) {
    failed_ = true;
    return {};
  }
  const auto out = in_.subspan(at_, n);
  at_ += n;
  return out;
}

std::string_view ByteReader::string() noexcept {
  const auto b = bytes(u32());
  return {reinterpret_cast<const char*>(b.data()), b.size()};
}

void Summary::count_message(std::uint16_t channel, std::uint64_t log_time) noexcept {
  if (message_count == 0 || log_time < message_start_time) message_start_time = log_time;
  if (message_count == 0 || log_time > message_end_time) message_end_time = log_time;
  ++message_count;
  if (channel < channel_message_count.size()) ++channel_message_count[channel];
}

void Summary::clear() noexcept {
  schemas.clear();
  channels.clear();
  chunks.clear();
  attachments.clear();
  metadata.clear();
  message_count = 0;
  channel_message_count.fill(0);
  message_start_time = message_end_time = 0;
}

void write_header(ByteWriter& w, std::string_view profile, std::string_view library) {
  const std::size_t r = w.begin_record(Op::kHeader);
  w.string(profile);
  w.string(library);
  w.end_record(r);
}

void write_schema(ByteWriter& w, const SchemaInfo& schema) {
  const std::size_t r = w.begin_record(Op::kSchema);
  w.u16(schema.id);
  w.string(schema.name);
  w.string(schema.encoding);
  w.string(schema.data);  // uint32 length + bytes, as a string is
  w.end_record(r);
}

void write_channel(ByteWriter& w, const ChannelInfo& channel) {
  const std::size_t r = w.begin_record(Op::kChannel);
  w.u16(channel.id);
  w.u16(channel.schema_id);
  w.string(channel.topic);
  w.string(channel.message_encoding);
  const std::size_t map = w.begin_u32_length();
  for (const auto& [key, value] : channel.metadata) {
    w.string(key);
    w.string(value);
  }
  w.end_u32_length(map);
  w.end_record(r);
}

void write_metadata(ByteWriter& w, std::string_view name,
                    std::span<const std::pair<std::string_view, std::string_view>> entries) {
  const std::size_t r = w.begin_record(Op::kMetadata);
  w.string(name);
  const std::size_t map = w.begin_u32_length();
  for (const auto& [key, value] : entries) {
    w.string(key);
    w.string(value);
  }
  w.end_u32_length(map);
  w.end_record(r);
}

void write_attachment(ByteWriter& w, std::uint64_t log_time, std::uint64_t create_time,
                      std::string_view name, std::string_view media_type,
                      std::span<const std::uint8_t> data) {
  const std::size_t r = w.begin_record(Op::kAttachment);
  const std::size_t crc_from = w.size();
  w.u64(log_time);
  w.u64(create_time);
  w.string(name);
  w.string(media_type);
  w.u64(data.size());
  w.bytes(data);
  w.u32(crc32(w.since(crc_from)));  // log_time through data
  w.end_record(r);
}

void write_message_prefix(ByteWriter& w, std::uint16_t channel, std::uint32_t sequence,
                          std::uint64_t log_time, std::uint64_t publish_time,
                          std::uint64_t data_bytes) {
  w.u8(static_cast<std::uint8_t>(Op::kMessage));
  w.u64(2 + 4 + 8 + 8 + data_bytes);
  w.u16(channel);
  w.u32(sequence);
  w.u64(log_time);
  w.u64(publish_time);
}

void write_chunk_header(ByteWriter& w, std::uint64_t message_start_time,
                        std::uint64_t message_end_time, std::uint64_t uncompressed_bytes,
                        std::uint32_t uncompressed_crc, std::string_view compression,
                        std::uint64_t stored_bytes) {
  // The length is known before the records follow: the fields below, then the records.
  w.u8(static_cast<std::uint8_t>(Op::kChunk));
  w.u64(chunk_header_bytes(compression) - kRecordPrefixBytes + stored_bytes);
  w.u64(message_start_time);
  w.u64(message_end_time);
  w.u64(uncompressed_bytes);
  w.u32(uncompressed_crc);
  w.string(compression);
  w.u64(stored_bytes);
}

void write_chunk(ByteWriter& w, std::uint64_t message_start_time, std::uint64_t message_end_time,
                 std::span<const std::uint8_t> uncompressed, std::string_view compression,
                 std::span<const std::uint8_t> stored) {
  write_chunk_header(w, message_start_time, message_end_time, uncompressed.size(),
                     crc32(uncompressed), compression, stored.size());
  w.bytes(stored);
}

void write_padding(std::span<std::uint8_t> out) noexcept {
  const std::uint64_t content = out.size() - kRecordPrefixBytes;
  out[0] = static_cast<std::uint8_t>(Op::kPadding);
  for (std::size_t i = 0; i < 8; ++i)
    out[1 + i] = static_cast<std::uint8_t>(content >> (8 * i));
  std::memset(out.data() + kRecordPrefixBytes, 0, content);
}

void write_message_index(ByteWriter& w, std::uint16_t channel,
                         std::span<const MessageIndexEntry> entries) {
  const std::size_t r = w.begin_record(Op::kMessageIndex);
  w.u16(channel);
  w.u32(static_cast<std::uint32_t>(entries.size() * 16));
  for (const MessageIndexEntry& e : entries) {
    w.u64(e.log_time);
    w.u64(e.offset);
  }
  w.end_record(r);
}

namespace {

void write_statistics(ByteWriter& w, const Summary& s) {
  const std::size_t r = w.begin_record(Op::kStatistics);
  w.u64(s.message_count);
  w.u16(static_cast<std::uint16_t>(s.schemas.size()));
  w.u32(static_cast<std::uint32_t>(s.channels.size()));
  w.u32(static_cast<std::uint32_t>(s.attachments.size()));
  w.u32(static_cast<std::uint32_t>(s.metadata.size()));
  w.u32(static_cast<std::uint32_t>(s.chunks.size()));
  w.u64(s.message_start_time);
  w.u64(s.message_end_time);
  const std::size_t map = w.begin_u32_length();
  for (const ChannelInfo& c : s.channels) {
    w.u16(c.id);
    w.u64(c.id < s.channel_message_count.size() ? s.channel_message_count[c.id] : 0);
  }
  w.end_u32_length(map);
  w.end_record(r);
}

void write_chunk_index(ByteWriter& w, const ChunkInfo& c) {
  const std::size_t r = w.begin_record(Op::kChunkIndex);
  w.u64(c.message_start_time);
  w.u64(c.message_end_time);
  w.u64(c.chunk_start_offset);
  w.u64(c.chunk_length);
  const std::size_t map = w.begin_u32_length();
  for (std::size_t i = 0; i < c.message_index_offset.size(); ++i) {
    if (c.message_index_offset[i] == 0) continue;
    w.u16(static_cast<std::uint16_t>(i + 1));
    w.u64(c.message_index_offset[i]);
  }
  w.end_u32_length(map);
  w.u64(c.message_index_length);
  w.string(c.compression);
  w.u64(c.compressed_size);
  w.u64(c.uncompressed_size);
  w.end_record(r);
}

void write_attachment_index(ByteWriter& w, const AttachmentInfo& a) {
  const std::size_t r = w.begin_record(Op::kAttachmentIndex);
  w.u64(a.offset);
  w.u64(a.length);
  w.u64(a.log_time);
  w.u64(a.create_time);
  w.u64(a.data_size);
  w.string(a.name);
  w.string(a.media_type);
  w.end_record(r);
}

void write_metadata_index(ByteWriter& w, const MetadataInfo& m) {
  const std::size_t r = w.begin_record(Op::kMetadataIndex);
  w.u64(m.offset);
  w.u64(m.length);
  w.string(m.name);
  w.end_record(r);
}

}  // namespace

void write_tail(ByteWriter& w, std::uint64_t data_end_offset, const Summary& s) {
  const std::size_t base = w.size();  // buffer position of data_end_offset
  const auto file_offset = [&] { return data_end_offset + (w.size() - base); };
  {
    const std::size_t r = w.begin_record(Op::kDataEnd);
    w.u32(0);  // data section CRC: not computed (each chunk carries its own)
    w.end_record(r);
  }
  const std::size_t summary_at = w.size();
  const std::uint64_t summary_start = file_offset();
  struct Group {
    Op op;
    std::uint64_t start, length;
  };
  std::array<Group, 6> groups{};
  std::size_t group_count = 0;
  const auto group = [&](Op op, std::size_t n, auto&& write_one) {
    if (n == 0) return;
    const std::uint64_t start = file_offset();
    for (std::size_t i = 0; i < n; ++i)
      write_one(i);
    groups[group_count++] = Group{op, start, file_offset() - start};
  };
  group(Op::kSchema, s.schemas.size(), [&](std::size_t i) { write_schema(w, s.schemas[i]); });
  group(Op::kChannel, s.channels.size(), [&](std::size_t i) { write_channel(w, s.channels[i]); });
  group(Op::kStatistics, 1, [&](std::size_t) { write_statistics(w, s); });
  group(Op::kChunkIndex, s.chunks.size(),
        [&](std::size_t i) { write_chunk_index(w, s.chunks[i]); });
  group(Op::kAttachmentIndex, s.attachments.size(),
        [&](std::size_t i) { write_attachment_index(w, s.attachments[i]); });
  group(Op::kMetadataIndex, s.metadata.size(),
        [&](std::size_t i) { write_metadata_index(w, s.metadata[i]); });
  const std::uint64_t summary_offset_start = file_offset();
  for (std::size_t i = 0; i < group_count; ++i) {
    const std::size_t r = w.begin_record(Op::kSummaryOffset);
    w.u8(static_cast<std::uint8_t>(groups[i].op));
    w.u64(groups[i].start);
    w.u64(groups[i].length);
    w.end_record(r);
  }
  // The footer's length is written before the CRC, which covers it: from the summary's start
  // through the footer's summary_offset_start field, the footer's opcode and length included.
  w.u8(static_cast<std::uint8_t>(Op::kFooter));
  w.u64(8 + 8 + 4);
  w.u64(summary_start);
  w.u64(summary_offset_start);
  w.u32(crc32(w.since(summary_at)));
  w.bytes(kMagic);
}

std::uint32_t crc32(std::span<const std::uint8_t> bytes, std::uint32_t crc) noexcept {
  // zlib takes uInt lengths: feed large spans in pieces.
  uLong c = crc;
  while (!bytes.empty()) {
    const std::size_t n = std::min<std::size_t>(bytes.size(), 1u << 30);
    c = ::crc32(c, bytes.data(), static_cast<uInt>(n));
    bytes = bytes.subspan(n);
  }
  return static_cast<std::uint32_t>(c);
}

}  // namespace pandarcap::mcap
