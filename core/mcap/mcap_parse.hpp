// Reading back the MCAP records pandarcap writes, from untrusted bytes: the recovery of a file a
// killed run left (daemon/mcap/mcap_recovery.hpp) parses each record it keeps, and the tests
// read files with it. Every parser checks lengths and returns nothing for a record that does not
// parse, never reading past the bytes given.
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <string_view>

#include "core/mcap/mcap_records.hpp"

namespace pandarcap::mcap {

// A record's opcode and content, seen through its 9-byte prefix.
struct RecordView {
  Op op{};
  std::span<const std::uint8_t> content;
};
// The record at the start of `bytes`, when all of it is there.
std::optional<RecordView> record_at(std::span<const std::uint8_t> bytes) noexcept;

std::optional<SchemaInfo> parse_schema(std::span<const std::uint8_t> content);
std::optional<ChannelInfo> parse_channel(std::span<const std::uint8_t> content);
// Attachment: its times, name, media type and data size (offset/length are the caller's).
std::optional<AttachmentInfo> parse_attachment(std::span<const std::uint8_t> content);
std::optional<std::string_view> parse_metadata_name(std::span<const std::uint8_t> content) noexcept;

struct ChunkView {
  std::uint64_t message_start_time = 0, message_end_time = 0, uncompressed_size = 0;
  std::uint32_t uncompressed_crc = 0;
  std::string_view compression;
  std::span<const std::uint8_t> records;  // as stored (compressed)
};
std::optional<ChunkView> parse_chunk(std::span<const std::uint8_t> content) noexcept;

struct MessageView {
  std::uint16_t channel = 0;
  std::uint32_t sequence = 0;
  std::uint64_t log_time = 0, publish_time = 0;
  std::span<const std::uint8_t> data;
};
std::optional<MessageView> parse_message(std::span<const std::uint8_t> content) noexcept;

// The channel a MessageIndex record indexes, when its entries' length is consistent.
std::optional<std::uint16_t> parse_message_index_channel(
    std::span<const std::uint8_t> content) noexcept;

}  // namespace pandarcap::mcap
