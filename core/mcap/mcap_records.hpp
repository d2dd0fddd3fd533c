// MCAP records, encoded as the public specification lays them out (https://mcap.dev/spec):
// little-endian integers, strings as uint32 length + bytes, maps and arrays as a uint32 byte
// length + entries, every record as opcode (1 byte) + content length (uint64) + content.
//
// This file is the encoding and decoding of single records and of the file's tail (data end,
// summary, summary offsets, footer, magic), shared by the recorder that writes files and by the
// recovery that finishes a file a killed run left. Pure logic: bytes in, bytes out, no I/O.
//
// pandarcap's files, in order:
//   magic, Header (profile "ros2"), Schema*, Channel*, Metadata, Attachment (calibration.csv),
//   Padding, { Chunk (compressed Message records), MessageIndex per channel in it, Padding }*,
//   DataEnd, summary (Schema*, Channel*, Statistics, ChunkIndex*, AttachmentIndex*,
//   MetadataIndex*), SummaryOffset per group, Footer, magic.
// Schemas and channels come before the first chunk, outside chunks, so a streaming reader knows
// them before any message, and a file cut anywhere keeps them.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace pandarcap::mcap {

inline constexpr std::array<std::uint8_t, 8> kMagic{0x89, 'M', 'C', 'A', 'P', '0', '\r', '\n'};

enum class Op : std::uint8_t {
  kHeader = 0x01,
  kFooter = 0x02,
  kSchema = 0x03,
  kChannel = 0x04,
  kMessage = 0x05,
  kChunk = 0x06,
  kMessageIndex = 0x07,
  kChunkIndex = 0x08,
  kAttachment = 0x09,
  kAttachmentIndex = 0x0A,
  kStatistics = 0x0B,
  kMetadata = 0x0C,
  kMetadataIndex = 0x0D,
  kSummaryOffset = 0x0E,
  kDataEnd = 0x0F,
  // pandarcap's own record (the spec leaves 0x80-0xFF to applications, and its readers skip an
  // opcode they do not know): zeros that end what the writer hands to the file on a 4096-byte
  // boundary, so that each chunk goes to the disk with O_DIRECT, past the page cache
  // (daemon/mcap/mcap_file.hpp). Its content means nothing.
  kPadding = 0x80,
};

// opcode + uint64 length.
inline constexpr std::size_t kRecordPrefixBytes = 9;
// A Message record's bytes before its data: prefix + channel (2) + sequence (4) + 2 times (16).
inline constexpr std::size_t kMessagePrefixBytes = kRecordPrefixBytes + 2 + 4 + 8 + 8;

// Appends to a byte vector. The recorder's vectors are reserved once, so appending within
// their capacity allocates nothing.
class ByteWriter {
 public:
  explicit ByteWriter(std::vector<std::uint8_t>& out) noexcept : out_(out) {}
  std::size_t size() const noexcept { return out_.size(); }
  void u8(std::uint8_t v) { out_.push_back(v); }
  void u16(std::uint16_t v) { little(v, 2); }
  void u32(std::uint32_t v) { little(v, 4); }
  void u64(std::uint64_t v) { little(v, 8); }
  void bytes(std::span<const std::uint8_t> b) { append(b.data(), b.size()); }
  void bytes(std::string_view s) { append(s.data(), s.size()); }
  void string(std::string_view s) {
    u32(static_cast<std::uint32_t>(s.size()));
    bytes(s);
  }
  // Opens a record: its opcode and a length patched by end_record(). Returns the handle.
  std::size_t begin_record(Op op);
  void end_record(std::size_t handle);
  // Opens a uint32 byte-length prefix (maps and arrays), closed by end_u32_length().
  std::size_t begin_u32_length();
  void end_u32_length(std::size_t handle);
  // Overwrites 8 bytes at `at` (a length or offset known only later).
  void patch_u64(std::size_t at, std::uint64_t v) noexcept;
  // What was appended from `from` on (for a CRC over part of a record).
  std::span<const std::uint8_t> since(std::size_t from) const noexcept {
    return std::span<const std::uint8_t>(out_).subspan(from);
  }

 private:
  void append(const void* data, std::size_t n) {
    if (n == 0) return;  // an empty span's data() may be null
    // insert copies into the room once; resize then memcpy wrote every byte twice (zeros
    // first): a frame's 2 MB of points, ten times a second, were a third of the MCAP writer's
    // samples in memset (docs/performance.md, ninth round).
    const auto* bytes = static_cast<const std::uint8_t*>(data);
    out_.insert(out_.end(), bytes, bytes + n);
  }
  void little(std::uint64_t v, int n) {
    for (int i = 0; i < n; ++i)
      out_.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
  }
  std::vector<std::uint8_t>& out_;
};

// Reads what ByteWriter writes, bounds-checked: a read past the end sets failed() and returns
// zeros/empties, so a parser over untrusted bytes checks once at the end.
class ByteReader {
 public:
  explicit ByteReader(std::span<const std::uint8_t> in) noexcept : in_(in) {}
  bool failed() const noexcept { return failed_; }
  std::size_t offset() const noexcept { return at_; }
  std::size_t remaining() const noexcept { return in_.size() - at_; }
  std::uint8_t u8() noexcept { return static_cast<std::uint8_t>(little(1)); }
  std::uint16_t u16() noexcept { return static_cast<std::uint16_t>(little(2)); }
  std::uint32_t u32() noexcept { return static_cast<std::uint32_t>(little(4)); }
  std::uint64_t u64() noexcept { return little(8); }
  std::span<const std::uint8_t> bytes(std::uint64_t n) noexcept;
  std::string_view string() noexcept;  // uint32 length + bytes

 private:
  std::uint64_t little(int n) noexcept;
  std::span<const std::uint8_t> in_;
  std::size_t at_ = 0;
  bool failed_ = false;
};

struct SchemaInfo {
  std::uint16_t id = 0;
  std::string name, encoding, data;
};
struct ChannelInfo {
  std::uint16_t id = 0, schema_id = 0;
  std::string topic, message_encoding;
  // The channel's metadata map (pandarcap's packets channel: sensor_model, docs/mcap.md).
  std::vector<std::pair<std::string, std::string>> metadata;
};
// One chunk as the summary's ChunkIndex records it.
struct ChunkInfo {
  std::uint64_t message_start_time = 0, message_end_time = 0;
  std::uint64_t chunk_start_offset = 0, chunk_length = 0;
  // MessageIndex record offsets, by channel (at most kMaxChannels, in channel order).
  std::array<std::uint64_t, 4> message_index_offset{};  // 0 = that channel has none here
  std::uint64_t message_index_length = 0;
  std::string_view compression;  // "zstd" or "" (a literal: the recorder's or recovery's)
  std::uint64_t compressed_size = 0, uncompressed_size = 0;
};
inline constexpr std::size_t kMaxChannels = 4;  // channel ids 1..kMaxChannels

struct AttachmentInfo {
  std::uint64_t offset = 0, length = 0, log_time = 0, create_time = 0, data_size = 0;
  std::string name, media_type;
};
struct MetadataInfo {
  std::uint64_t offset = 0, length = 0;
  std::string name;
};

// Everything the tail of a file states about the data before it.
struct Summary {
  std::vector<SchemaInfo> schemas;
  std::vector<ChannelInfo> channels;
  std::vector<ChunkInfo> chunks;
  std::vector<AttachmentInfo> attachments;
  std::vector<MetadataInfo> metadata;
  std::uint64_t message_count = 0;
  std::array<std::uint64_t, kMaxChannels + 1> channel_message_count{};  // by channel id
  std::uint64_t message_start_time = 0, message_end_time = 0;           // of all messages
  void count_message(std::uint16_t channel, std::uint64_t log_time) noexcept;
  void clear() noexcept;
};

void write_header(ByteWriter& w, std::string_view profile, std::string_view library);
void write_schema(ByteWriter& w, const SchemaInfo& schema);
void write_channel(ByteWriter& w, const ChannelInfo& channel);
// A Metadata record of string pairs.
void write_metadata(ByteWriter& w, std::string_view name,
                    std::span<const std::pair<std::string_view, std::string_view>> entries);
// An Attachment record; its CRC32 is computed.
void write_attachment(ByteWriter& w, std::uint64_t log_time, std::uint64_t create_time,
                      std::string_view name, std::string_view media_type,
                      std::span<const std::uint8_t> data);

// The header of a Message record whose `data_bytes` of data the caller appends next.
void write_message_prefix(ByteWriter& w, std::uint16_t channel, std::uint32_t sequence,
                          std::uint64_t log_time, std::uint64_t publish_time,
                          std::uint64_t data_bytes);

// A Chunk record around `records` (compressed as `compression` says: `stored` is what goes in
// the file, `uncompressed` is used for the size and CRC).
void write_chunk(ByteWriter& w, std::uint64_t message_start_time, std::uint64_t message_end_time,
                 std::span<const std::uint8_t> uncompressed, std::string_view compression,
                 std::span<const std::uint8_t> stored);
// The same Chunk record up to its stored records, which the caller writes next
// (`stored_bytes` of them): the writer sends a compressed chunk to the file without copying it.
// The records' size and CRC-32 are given, computed where the chunk was compressed.
void write_chunk_header(ByteWriter& w, std::uint64_t message_start_time,
                        std::uint64_t message_end_time, std::uint64_t uncompressed_bytes,
                        std::uint32_t uncompressed_crc, std::string_view compression,
                        std::uint64_t stored_bytes);
// The bytes write_chunk_header() writes for a chunk compressed as `compression`: the record's
// prefix, its times (2 x 8), the uncompressed size (8), the CRC (4), the compression as a string
// (4 + its length) and the stored records' length (8).
constexpr std::size_t chunk_header_bytes(std::string_view compression) noexcept {
  return kRecordPrefixBytes + 8 + 8 + 8 + 4 + 4 + compression.size() + 8;
}
// The length of the Padding record that takes `end` to the next multiple of `block`: at least
// its 9-byte prefix, so a whole block more when fewer bytes are left to it.
constexpr std::size_t padding_bytes(std::size_t end, std::size_t block) noexcept {
  const std::size_t to_block = (block - end % block) % block;
  return to_block >= kRecordPrefixBytes ? to_block : to_block + block;
}
// A Padding record of exactly `out.size()` bytes (at least kRecordPrefixBytes) in `out`.
void write_padding(std::span<std::uint8_t> out) noexcept;
// A MessageIndex record: (log_time, offset in the chunk's uncompressed records) pairs.
struct MessageIndexEntry {
  std::uint64_t log_time = 0, offset = 0;
};
void write_message_index(ByteWriter& w, std::uint16_t channel,
                         std::span<const MessageIndexEntry> entries);

// DataEnd, the summary section, the summary offsets, the footer and the closing magic, for a file
// whose data section ends at `data_end_offset` (where these bytes will start).
void write_tail(ByteWriter& w, std::uint64_t data_end_offset, const Summary& summary);

// CRC-32 (ISO-HDLC, zlib's), as MCAP uses for chunks, attachments and the summary.
std::uint32_t crc32(std::span<const std::uint8_t> bytes, std::uint32_t crc = 0) noexcept;

}  // namespace pandarcap::mcap
