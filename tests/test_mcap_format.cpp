// core/mcap: the MCAP records, the CDR-encoded ROS 2 messages and chunk compression, on bytes.
// Whole files are read back by the MCAP project's own reader in test_mcap_file.cpp and
// test_mcap_output.cpp; here each piece is checked against the specification's layout.
#include <catch2/catch.hpp>
#include <cstdint>
#include <numeric>
#include <random>
#include <string>
#include <vector>

#include "core/frames/pcd.hpp"
#include "core/mcap/chunk_codec.hpp"
#include "core/mcap/mcap_parse.hpp"
#include "core/mcap/mcap_records.hpp"
#include "core/mcap/ros2_messages.hpp"

using namespace pandarcap;
using namespace pandarcap::mcap;

namespace {

std::span<const std::uint8_t> bytes_of(std::string_view s) {
  return {reinterpret_cast<const std::uint8_t*>(s.data()), s.size()};
}

std::uint32_t u32_at(const std::vector<std::uint8_t>& b, std::size_t at) {
  return b[at] | b[at + 1] << 8 | b[at + 2] << 16 | static_cast<std::uint32_t>(b[at + 3]) << 24;
}

}  // namespace

TEST_CASE("MCAP CRC-32 is zlib's ISO-HDLC CRC, also over pieces", "[mcap]") {
  CHECK(crc32(bytes_of("123456789")) == 0xCBF43926u);  // the standard check value
  CHECK(crc32(bytes_of("")) == 0u);
  CHECK(crc32(bytes_of("6789"), crc32(bytes_of("12345"))) == 0xCBF43926u);
}

TEST_CASE("MCAP records have opcode, uint64 length and the specification's fields", "[mcap]") {
  std::vector<std::uint8_t> out;
  ByteWriter w(out);
  write_schema(w, SchemaInfo{7, "a/msg/B", "ros2msg", "int32 x\n"});
  REQUIRE(out.size() == 9 + 2 + (4 + 7) + (4 + 7) + (4 + 8));
  CHECK(out[0] == 0x03);
  CHECK(out[1] == out.size() - 9);
  const auto record = record_at(out);
  REQUIRE(record);
  CHECK(record->op == Op::kSchema);
  const auto schema = parse_schema(record->content);
  REQUIRE(schema);
  CHECK(schema->id == 7);
  CHECK(schema->name == "a/msg/B");
  CHECK(schema->encoding == "ros2msg");
  CHECK(schema->data == "int32 x\n");

  out.clear();
  write_channel(w, ChannelInfo{3, 7, "/pandar/points", "cdr", {}});
  const auto channel = parse_channel(record_at(out)->content);
  REQUIRE(channel);
  CHECK(channel->id == 3);
  CHECK(channel->schema_id == 7);
  CHECK(channel->topic == "/pandar/points");
  CHECK(channel->message_encoding == "cdr");
  CHECK(channel->metadata.empty());

  // A channel's metadata map (the packets channel's sensor_model), kept entry for entry.
  out.clear();
  write_channel(
      w, ChannelInfo{3, 3, "/pandar/packets", "cdr", {{"sensor_model", "PandarXT32"}, {"k", ""}}});
  const auto packets = parse_channel(record_at(out)->content);
  REQUIRE(packets);
  REQUIRE(packets->metadata.size() == 2);
  CHECK(packets->metadata[0] == std::pair<std::string, std::string>("sensor_model", "PandarXT32"));
  CHECK(packets->metadata[1] == std::pair<std::string, std::string>("k", ""));

  out.clear();
  const std::string csv = "Channel,Elevation,Azimuth\n1,15,-1\n";
  write_attachment(w, 11, 22, "calibration.csv", "text/csv", bytes_of(csv));
  auto attachment = parse_attachment(record_at(out)->content);
  REQUIRE(attachment);
  CHECK(attachment->log_time == 11);
  CHECK(attachment->create_time == 22);
  CHECK(attachment->name == "calibration.csv");
  CHECK(attachment->data_size == csv.size());
  // The CRC covers the data: one flipped byte is refused.
  out[out.size() - 10] ^= 1;
  CHECK_FALSE(parse_attachment(record_at(out)->content));
}

TEST_CASE("MCAP message prefix, chunk and message index round trip", "[mcap]") {
  std::vector<std::uint8_t> records;
  ByteWriter r(records);
  const std::string data = "{\"state\":\"ok\"}";
  write_message_prefix(r, 2, 41, 1000, 1001, data.size());
  CHECK(records.size() == kMessagePrefixBytes);
  r.bytes(data);
  const auto message = parse_message(record_at(records)->content);
  REQUIRE(message);
  CHECK(message->channel == 2);
  CHECK(message->sequence == 41);
  CHECK(message->log_time == 1000);
  CHECK(message->publish_time == 1001);
  CHECK(std::string(message->data.begin(), message->data.end()) == data);

  ChunkCompressor compressor(ChunkCompression::kZstd, records.size());
  std::vector<std::uint8_t> compressed(compressor.bound());
  compressed.resize(compressor.compress(records, compressed));
  std::vector<std::uint8_t> out;
  ByteWriter w(out);
  write_chunk(w, 1000, 1000, records, "zstd", compressed);
  const auto chunk = parse_chunk(record_at(out)->content);
  REQUIRE(chunk);
  CHECK(chunk->compression == "zstd");
  CHECK(chunk->uncompressed_size == records.size());
  CHECK(chunk->uncompressed_crc == crc32(records));
  // The header alone, the stored records written after it, is the same record.
  std::vector<std::uint8_t> split;
  ByteWriter s(split);
  write_chunk_header(s, 1000, 1000, records.size(), crc32(records), "zstd", compressed.size());
  s.bytes(compressed);
  CHECK(split == out);
  std::vector<std::uint8_t> back(chunk->uncompressed_size);
  REQUIRE(decompress_chunk(chunk->compression, chunk->records, back));
  CHECK(back == records);
  // Wrong size, unknown compression, damaged bytes: refused, never a read past the buffers.
  std::vector<std::uint8_t> wrong(records.size() + 1);
  CHECK_FALSE(decompress_chunk("zstd", chunk->records, wrong));
  CHECK_FALSE(decompress_chunk("lz4", chunk->records, back));
  CHECK_FALSE(decompress_chunk("brotli", chunk->records, back));
  std::vector<std::uint8_t> damaged(chunk->records.begin(), chunk->records.end());
  damaged.resize(damaged.size() / 2);
  CHECK_FALSE(decompress_chunk("zstd", damaged, back));

  out.clear();
  const std::vector<MessageIndexEntry> entries{{1000, 0}, {2000, 77}};
  write_message_index(w, 2, entries);
  CHECK(out.size() == 9 + 2 + 4 + 32);
  CHECK(parse_message_index_channel(record_at(out)->content) == std::optional<std::uint16_t>(2));
}

TEST_CASE("lz4 chunks: the LZ4 frame format, its stated size, round trip and damage refused",
          "[mcap]") {
  CHECK(compression_name(ChunkCompression::kLz4) == "lz4");
  CHECK(parse_compression_name("lz4") == ChunkCompression::kLz4);
  CHECK(parse_compression_name("") == ChunkCompression::kNone);
  CHECK_FALSE(parse_compression_name("bz2"));
  // Records like a frame's: repetitive, several LZ4 blocks' worth (over 4 MB) plus some.
  std::vector<std::uint8_t> records(5'000'000);
  for (std::size_t i = 0; i < records.size(); ++i)
    records[i] = static_cast<std::uint8_t>((i % 23) * 7 + (i / 4096) % 5);
  for (const int level : {1, -3, 9}) {
    INFO("level " << level);
    ChunkCompressor compressor(ChunkCompression::kLz4, records.size(), level);
    std::vector<std::uint8_t> stored(compressor.bound());
    stored.resize(compressor.compress(records, stored));
    CHECK(stored.size() < records.size() / 2);
    // The LZ4 frame's magic number (0x184D2204, little-endian): a frame, not a raw block.
    REQUIRE(stored.size() > 4);
    CHECK(std::vector<std::uint8_t>(stored.begin(), stored.begin() + 4) ==
          std::vector<std::uint8_t>{0x04, 0x22, 0x4D, 0x18});
    CHECK(stored_content_size("lz4", stored) == records.size());
    std::vector<std::uint8_t> back(records.size());
    REQUIRE(decompress_chunk("lz4", stored, back));
    CHECK(back == records);
    std::vector<std::uint8_t> wrong(records.size() - 1);
    CHECK_FALSE(decompress_chunk("lz4", stored, wrong));
    CHECK_FALSE(decompress_chunk("zstd", stored, back));
    const std::vector<std::uint8_t> cut(
        stored.begin(), stored.begin() + static_cast<std::ptrdiff_t>(stored.size() / 2));
    CHECK_FALSE(decompress_chunk("lz4", cut, back));
    // A damaged frame header fails its header checksum. Damaged blocks are refused or come out
    // different (no content checksum: the chunk's CRC-32 is what refuses them), never read or
    // written past the buffers.
    std::vector<std::uint8_t> damaged = stored;
    damaged[5] ^= 0x10;
    CHECK_FALSE(decompress_chunk("lz4", damaged, back));
    damaged = stored;
    for (std::size_t i = 64; i < damaged.size(); i += 101)
      damaged[i] ^= 0x5A;
    if (decompress_chunk("lz4", damaged, back)) CHECK(crc32(back) != crc32(records));
  }
  CHECK_FALSE(stored_content_size("lz4", std::vector<std::uint8_t>{1, 2, 3}));
}

TEST_CASE("MCAP parsers refuse every truncation of a record", "[mcap]") {
  std::vector<std::uint8_t> out;
  ByteWriter w(out);
  write_schema(w, SchemaInfo{1, "n", "ros2msg", "int8 a\n"});
  write_channel(w, ChannelInfo{1, 1, "/t", "cdr", {{"sensor_model", "Pandar64"}}});
  write_attachment(w, 1, 2, "c.csv", "text/csv", bytes_of("abc"));
  const std::vector<std::uint8_t> payload(100, 0x55);
  write_chunk(w, 1, 2, payload, "", payload);
  std::span<const std::uint8_t> rest(out);
  int records = 0;
  while (!rest.empty()) {
    const auto record = record_at(rest);
    REQUIRE(record);
    const std::size_t length = kRecordPrefixBytes + record->content.size();
    // The record cut short: record_at refuses it; its content cut short: its parser refuses it.
    for (std::size_t n = 0; n < length; ++n)
      CHECK_FALSE(record_at(rest.first(n)));
    for (std::size_t n = 0; n < record->content.size(); ++n) {
      const auto cut = record->content.first(n);
      switch (record->op) {
        case Op::kSchema:
          CHECK_FALSE(parse_schema(cut));
          break;
        case Op::kChannel:
          CHECK_FALSE(parse_channel(cut));
          break;
        case Op::kAttachment:
          CHECK_FALSE(parse_attachment(cut));
          break;
        case Op::kChunk:
          CHECK_FALSE(parse_chunk(cut));
          break;
        default:
          FAIL("unexpected record");
      }
    }
    rest = rest.subspan(length);
    ++records;
  }
  CHECK(records == 4);
  // A length field that claims more than there is: refused, not trusted.
  std::vector<std::uint8_t> lying = out;
  lying[1] = 0xFF;
  lying[8] = 0x7F;
  CHECK_FALSE(record_at(lying));
}

TEST_CASE("CDR PointCloud2: the prefix length is what is written, fields as the PCD's",
          "[mcap][cdr]") {
  for (const PcdLayout layout :
       {PcdLayout::kPcl, PcdLayout::kPandarcap, PcdLayout::kVelodyne, PcdLayout::kAutoware}) {
    const std::uint32_t step = static_cast<std::uint32_t>(pcd_point_bytes(layout));
    // Frame ids of every length modulo 4 exercise every alignment of what follows the string.
    for (const std::string frame_id : {"", "p", "pa", "pan", "pandar", "vehicle/lidar_front"}) {
      for (const std::uint32_t points : {0u, 1u, 72000u}) {
        std::vector<std::uint8_t> out{0xAA, 0xBB, 0xCC};  // not at the buffer's start
        ByteWriter w(out);
        write_pointcloud2_prefix(w, RosTime{1'700'000'000, 5}, frame_id, points, layout);
        INFO("layout " << to_string(layout) << ", frame_id '" << frame_id << "', " << points
                       << " points");
        REQUIRE(out.size() - 3 == pointcloud2_prefix_bytes(frame_id.size(), layout));
        // The data length is the prefix's last field, and row_step and point_step precede it.
        CHECK(u32_at(out, out.size() - 4) == points * step);
        CHECK(u32_at(out, out.size() - 8) == points * step);
        CHECK(u32_at(out, out.size() - 12) == step);
        // Encapsulation: plain CDR, little-endian; then stamp and the NUL-terminated frame id.
        CHECK(out[3] == 0);
        CHECK(out[4] == 1);
        CHECK(u32_at(out, 7) == 1'700'000'000u);
        CHECK(u32_at(out, 11) == 5u);
        CHECK(u32_at(out, 15) == frame_id.size() + 1);
        CHECK(out[19 + frame_id.size()] == 0);
        // height 1, width, then one PointField per PCD field: name, offset, datatype, count.
        std::size_t at = 3 + 4 + 8 + 4 + frame_id.size() + 1;
        at = 3 + 4 + (at - 7 + 3) / 4 * 4;
        CHECK(u32_at(out, at) == 1);
        CHECK(u32_at(out, at + 4) == points);
        const auto fields = pcd_fields(layout);
        REQUIRE(u32_at(out, at + 8) == fields.size());
        at += 12;
        for (const PcdField& f : fields) {
          INFO("field " << f.name);
          REQUIRE(u32_at(out, at) == f.name.size() + 1);
          CHECK(std::string_view(reinterpret_cast<const char*>(out.data() + at + 4),
                                 f.name.size()) == f.name);
          at += 4 + f.name.size() + 1;
          at = 3 + 4 + (at - 7 + 3) / 4 * 4;
          CHECK(u32_at(out, at) == f.offset);
          const std::uint8_t datatype = out[at + 4];
          // sensor_msgs/PointField: UINT8 2, UINT16 4, UINT32 6, FLOAT32 7, FLOAT64 8.
          const std::uint8_t expected = f.type == 'F' ? (f.size == 8 ? 8 : 7)
                                        : f.size == 1 ? 2
                                        : f.size == 2 ? 4
                                                      : 6;
          CHECK(datatype == expected);
          at += 5;
          at = 3 + 4 + (at - 7 + 3) / 4 * 4;
          CHECK(u32_at(out, at) == 1);
          at += 4;
        }
      }
    }
  }
}

TEST_CASE("CDR PandarPacket: its length is what is written, size after aligned data",
          "[mcap][cdr]") {
  for (const std::size_t size : {0u, 1u, 2u, 3u, 1262u, 1266u}) {
    std::vector<std::uint8_t> payload(size);
    std::iota(payload.begin(), payload.end(), std::uint8_t{1});
    std::vector<std::uint8_t> out;
    ByteWriter w(out);
    write_pandar_packet(w, RosTime{12, 34}, payload);
    INFO(size << " bytes");
    REQUIRE(out.size() == pandar_packet_bytes(size));
    CHECK(u32_at(out, 12) == size);
    CHECK(std::equal(payload.begin(), payload.end(), out.begin() + 16));
    CHECK(u32_at(out, out.size() - 4) == size);
    CHECK((out.size() - 4 - 4) % 4 == 0);  // the size field is aligned after the header
  }
}

TEST_CASE("ROS times floor toward the past, nanoseconds always under a second", "[mcap][cdr]") {
  CHECK(ros_time(1'500'000'000'123'456'789).sec == 1'500'000'000);
  CHECK(ros_time(1'500'000'000'123'456'789).nanosec == 123'456'789u);
  CHECK(ros_time(-1).sec == -1);
  CHECK(ros_time(-1).nanosec == 999'999'999u);
  CHECK(ros_time(0).sec == 0);
}

TEST_CASE("MCAP tail: summary offsets point at their groups, footer CRC covers the summary",
          "[mcap]") {
  Summary s;
  s.schemas.push_back({1, "a", "ros2msg", "int8 x\n"});
  s.channels.push_back({1, 1, "/a", "cdr", {}});
  ChunkInfo chunk;
  chunk.chunk_start_offset = 100;
  chunk.chunk_length = 50;
  chunk.message_index_offset[0] = 150;
  chunk.message_index_length = 25;
  chunk.compression = "zstd";
  s.chunks.push_back(chunk);
  s.count_message(1, 5);
  s.count_message(1, 3);
  CHECK(s.message_start_time == 3);
  CHECK(s.message_end_time == 5);
  const std::uint64_t data_end = 1000;
  std::vector<std::uint8_t> out;
  ByteWriter w(out);
  write_tail(w, data_end, s);
  REQUIRE(out.size() > 8 + 29);
  CHECK(std::equal(kMagic.begin(), kMagic.end(), out.end() - 8));
  // Footer: opcode, length 20, summary start, summary offset start, CRC.
  const std::size_t footer = out.size() - 8 - 29;
  CHECK(out[footer] == static_cast<std::uint8_t>(Op::kFooter));
  CHECK(out[footer + 1] == 20);
  const auto at = [&](std::size_t i) {
    std::uint64_t v = 0;
    for (int b = 7; b >= 0; --b)
      v = v << 8 | out[i + b];
    return v;
  };
  const std::uint64_t summary_start = at(footer + 9);
  const std::uint64_t offsets_start = at(footer + 17);
  CHECK(summary_start == data_end + 13);  // after DataEnd (9 + 4)
  const std::size_t summary_in_buffer = summary_start - data_end;
  CHECK(u32_at(out, footer + 25) ==
        crc32(std::span(out).subspan(summary_in_buffer, footer + 25 - summary_in_buffer)));
  // Every summary offset names a group that starts with records of its opcode.
  int groups = 0;
  for (std::size_t i = offsets_start - data_end; i < footer; i += 9 + 17) {
    REQUIRE(out[i] == static_cast<std::uint8_t>(Op::kSummaryOffset));
    const std::uint8_t op = out[i + 9];
    const std::uint64_t group_start = at(i + 10) - data_end;
    CHECK(out[group_start] == op);
    ++groups;
  }
  CHECK(groups == 4);  // schema, channel, statistics, chunk index
}

TEST_CASE("a chunk's stored size is read from its zstd frame header before any decompression",
          "[mcap]") {
  std::vector<std::uint8_t> records(100'000, 0x42);
  ChunkCompressor compressor(ChunkCompression::kZstd, records.size());
  std::vector<std::uint8_t> compressed(compressor.bound());
  compressed.resize(compressor.compress(records, compressed));
  CHECK(stored_content_size("zstd", compressed) == std::optional<std::uint64_t>(100'000));
  CHECK(stored_content_size("", compressed) == std::optional<std::uint64_t>(compressed.size()));
  CHECK_FALSE(stored_content_size("lz4", compressed));
  const std::vector<std::uint8_t> garbage(16, 0xAB);
  CHECK_FALSE(stored_content_size("zstd", garbage));
  CHECK_FALSE(stored_content_size("zstd", std::span<const std::uint8_t>()));
}
