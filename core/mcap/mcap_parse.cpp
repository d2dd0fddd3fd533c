#include "core/mcap/mcap_parse.hpp"

#include <string>

namespace pandarcap::mcap {

std::optional<RecordView> record_at(std::span<const std::uint8_t> bytes) noexcept {
  ByteReader r(bytes);
  const auto op = static_cast<Op>(r.u8());
  const std::uint64_t length = r.u64();
  const auto content = r.bytes(length);
  if (r.failed()) return std::nullopt;
  return RecordView{op, content};
}

std::optional<SchemaInfo> parse_schema(std::span<const std::uint8_t> content) {
  ByteReader r(content);
  SchemaInfo s;
  s.id = r.u16();
  s.name = r.string();
  s.encoding = r.string();
  s.data = r.string();
  if (r.failed() || r.remaining() != 0 || s.id == 0) return std::nullopt;
  return s;
}

std::optional<ChannelInfo> parse_channel(std::span<const std::uint8_t> content) {
  ByteReader r(content);
  ChannelInfo c;
  c.id = r.u16();
  c.schema_id = r.u16();
  c.topic = r.string();
  c.message_encoding = r.string();
  // The metadata map: kept (a recovered file's summary repeats it), each entry whole.
  ByteReader map(r.bytes(r.u32()));
  while (!map.failed() && map.remaining() > 0) {
    const std::string_view key = map.string();
    const std::string_view value = map.string();
    if (!map.failed()) c.metadata.emplace_back(key, value);
  }
  if (r.failed() || map.failed() || r.remaining() != 0 || c.id == 0 || c.id > kMaxChannels) {
    return std::nullopt;
  }
  return c;
}

std::optional<AttachmentInfo> parse_attachment(std::span<const std::uint8_t> content) {
  ByteReader r(content);
  AttachmentInfo a;
  a.log_time = r.u64();
  a.create_time = r.u64();
  a.name = r.string();
  a.media_type = r.string();
  a.data_size = r.u64();
  const std::size_t crc_covers = r.offset() + a.data_size;
  r.bytes(a.data_size);
  const std::uint32_t crc = r.u32();
  if (r.failed() || r.remaining() != 0) return std::nullopt;
  if (crc != 0 && crc != crc32(content.first(crc_covers))) return std::nullopt;
  return a;
}

std::optional<std::string_view> parse_metadata_name(
    std::span<const std::uint8_t> content) noexcept {
  ByteReader r(content);
  const std::string_view name = r.string();
  r.bytes(r.u32());
  if (r.failed() || r.remaining() != 0) return std::nullopt;
  return name;
}

std::optional<ChunkView> parse_chunk(std::span<const std::uint8_t> content) noexcept {
  ByteReader r(content);
  ChunkView c;
  c.message_start_time = r.u64();
  c.message_end_time = r.u64();
  c.uncompressed_size = r.u64();
  c.uncompressed_crc = r.u32();
  c.compression = r.string();
  c.records = r.bytes(r.u64());
  if (r.failed() || r.remaining() != 0) return std::nullopt;
  return c;
}

std::optional<MessageView> parse_message(std::span<const std::uint8_t> content) noexcept {
  ByteReader r(content);
  MessageView m;
  m.channel = r.u16();
  m.sequence = r.u32();
  m.log_time = r.u64();
  m.publish_time = r.u64();
  if (r.failed()) return std::nullopt;
  m.data = r.bytes(r.remaining());
  return m;
}

std::optional<std::uint16_t> parse_message_index_channel(
    std::span<const std::uint8_t> content) noexcept {
  ByteReader r(content);
  const std::uint16_t channel = r.u16();
  const std::uint32_t length = r.u32();
  r.bytes(length);
  if (r.failed() || r.remaining() != 0 || length % 16 != 0) return std::nullopt;
  return channel;
}

}  // namespace pandarcap::mcap
