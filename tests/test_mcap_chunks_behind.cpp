// daemon/mcap: a chunk the compression thread takes while a full chunk waits behind it is stored
// as it is (compression "", its CRC always computed), live only (chunk_pipeline.hpp). The
// pipeline's decision, the files it makes (read by our parser, the next start's recovery and the
// MCAP project's own reader), and the chunks a flush or a close hands over, which never count as
// compression behind. The compression thread runs in every test: [threads].
#include <algorithm>
#include <catch2/catch.hpp>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <random>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "bench/child_process.hpp"
#include "core/mcap/chunk_codec.hpp"
#include "core/mcap/mcap_parse.hpp"
#include "daemon/mcap/chunk_pipeline.hpp"
#include "daemon/mcap/mcap_file.hpp"
#include "daemon/mcap/mcap_recovery.hpp"
#include "support/mcap_data_records.hpp"
#include "support/mcap_reader.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
namespace fs = std::filesystem;
using namespace std::chrono_literals;

namespace {

constexpr std::uint64_t kBehindT0 = 1'795'348'800'000'000'000;  // 2026-11-20, ns

// Records a compressor takes its time over: words from a small vocabulary in a random order.
// zstd at level 19 spends about half a second on 1 MiB of them here, where handing a chunk over
// takes microseconds.
std::vector<std::uint8_t> wordy_bytes(std::size_t bytes, unsigned seed) {
  static constexpr std::string_view kWords[] = {"lidar ",   "frame ",  "packet ", "chunk ",
                                                "azimuth ", "return ", "block ",  "channel "};
  std::mt19937 random(seed);
  std::vector<std::uint8_t> out;
  out.reserve(bytes + 16);
  while (out.size() < bytes) {
    const std::string_view word = kWords[random() % std::size(kWords)];
    out.insert(out.end(), word.begin(), word.end());
  }
  out.resize(bytes);
  return out;
}

// A live file (never waiting for a chunk buffer) of 64 kB chunks with packets.
McapFileOptions live_options(mcap::ChunkCompression compression, int level) {
  McapFileOptions o;
  o.compression = compression;
  o.compression_level = level;
  o.chunk_bytes = 64 * 1024;
  o.max_frame_points = 4000;
  o.max_chunks = 4096;
  o.packets = true;
  o.library = "pandarcap test";
  o.calibration_csv = "Channel,Elevation,Azimuth\n1,15,0\n";
  o.sensor_model = "Pandar64";
  o.wait_for_free_chunk = false;
  return o;
}

struct StoredChunk {
  std::string compression;
  std::uint32_t crc = 0;
  bool crc_matches = false;  // the CRC said, of the records as stored (uncompressed chunks)
  std::size_t offset = 0;    // of the Chunk record in the file
  std::size_t records_offset = 0, records_bytes = 0;  // its records as stored, in the file
};

// An MCAP file's data section as our own parser reads it: each Chunk record in file order, and
// where the DataEnd record begins (the data section's end).
struct DataSection {
  std::vector<StoredChunk> chunks;
  std::size_t end = 0;
};
DataSection data_section(const std::string& bytes) {
  DataSection out;
  for (const test::DataRecord& record : test::data_records(bytes)) {
    if (record.op == mcap::Op::kDataEnd) out.end = record.at;
    if (record.op != mcap::Op::kChunk) continue;
    const auto chunk = mcap::parse_chunk(record.content);
    REQUIRE(chunk);
    out.chunks.push_back(
        {std::string(chunk->compression), chunk->uncompressed_crc,
         chunk->uncompressed_crc == mcap::crc32(chunk->records), record.at,
         static_cast<std::size_t>(chunk->records.data() -
                                  reinterpret_cast<const std::uint8_t*>(bytes.data())),
         chunk->records.size()});
  }
  return out;
}

// Each Chunk record of the MCAP file at `path`, in file order.
std::vector<StoredChunk> chunks_in(const fs::path& path) {
  return data_section(harness::read_file(path)).chunks;
}

// What a live file written as fast as the loop goes held, once closed.
struct WrittenFast {
  std::uint64_t in_file = 0;       // packets add_packet() took
  std::uint64_t messages = 0;      // in the file's chunks
  std::uint64_t not_recorded = 0;  // left out: no free chunk buffer
  std::uint64_t stored = 0;        // chunks stored as they are
};

// A live file at `path` with zstd at level 19 and 64 kB chunks, given `count` packets (words, so
// that they compress) as fast as the loop goes, then closed: the compression thread is behind
// from the second chunk on.
WrittenFast write_fast(const fs::path& path, int count, unsigned seed) {
  McapFile file(live_options(mcap::ChunkCompression::kZstd, 19));
  file.open(path.string(), kBehindT0);
  const auto payloads = wordy_bytes(1262 * 64, seed);
  WrittenFast w;
  for (int i = 0; i < count; ++i) {
    const std::uint64_t t = kBehindT0 + static_cast<std::uint64_t>(i) * 1000;
    const auto payload = std::span(payloads).subspan(static_cast<std::size_t>(i % 64) * 1262, 1262);
    w.in_file += file.add_packet(payload, static_cast<std::int64_t>(t), t);
  }
  file.close();
  w.messages = file.messages();
  w.not_recorded = file.messages_not_recorded();
  w.stored = file.chunks_uncompressed();
  return w;
}

}  // namespace

TEST_CASE("a chunk taken while a full chunk waits behind it is stored uncompressed",
          "[mcap][threads]") {
  const bool when_behind = GENERATE(true, false);
  INFO("uncompressed_when_behind " << when_behind);
  constexpr std::size_t kFirst = 1u << 20, kOthers = 64u << 10;
  ChunkPipeline pipeline(4, kFirst, 16, mcap::ChunkCompression::kZstd, 19, false, when_behind);
  // 0, 1 and 2 full; 3 handed over by a close (not full).
  const std::vector<std::size_t> sizes{kFirst, kOthers, kOthers, kOthers};
  const std::vector<bool> full{true, true, true, false};
  std::vector<ChunkBuffer*> chunks;
  for (unsigned i = 0; i < 4; ++i) {
    ChunkBuffer* chunk = pipeline.take_free();
    REQUIRE(chunk != nullptr);
    const auto records = wordy_bytes(sizes[i], i);
    chunk->records.assign(records.begin(), records.end());
    chunk->messages = 1;
    chunk->full = full[i];
    chunks.push_back(chunk);
  }
  // The first alone, until the thread has taken it up and decided: nothing was behind it, so
  // it is compressed, which takes long enough for the other three to queue behind it.
  pipeline.submit(chunks[0]);
  REQUIRE(harness::wait_until([&] { return pipeline.taken() == 1; }, 10s));
  for (unsigned i = 1; i < 4; ++i)
    pipeline.submit(chunks[i]);
  std::vector<bool> uncompressed;
  for (unsigned i = 0; i < 4; ++i) {
    ChunkBuffer* chunk = pipeline.wait_done();
    REQUIRE(chunk == chunks[i]);  // back in the order handed over
    INFO("chunk " << i);
    REQUIRE_FALSE(chunk->failed);
    uncompressed.push_back(chunk->uncompressed);
    const auto expected = wordy_bytes(sizes[i], i);
    if (chunk->uncompressed) {
      CHECK(std::ranges::equal(chunk->stored(), expected));
      CHECK(chunk->crc == mcap::crc32(expected));  // always, though the pipeline's CRC is off
    } else {
      CHECK(chunk->crc == 0);
      CHECK(chunk->stored().size() < expected.size() / 2);
      std::vector<std::uint8_t> out(expected.size());
      CHECK(mcap::decompress_chunk("zstd", chunk->stored(), out));
      CHECK(out == expected);
    }
    pipeline.give_back(chunk);
    CHECK_FALSE(chunk->uncompressed);  // cleared for its next use
    CHECK_FALSE(chunk->full);
  }
  // 1 had the full 2 behind it; 2 had only 3, which a close handed over; 0 and 3 had none.
  CHECK(uncompressed == std::vector<bool>{false, when_behind, false, false});
}

TEST_CASE("live: compression a chunk behind stores chunks as they are and the file reads whole",
          "[mcap][threads]") {
  test::ScratchDir dir("mcap-behind");
  const fs::path path = dir / "a.mcap";
  constexpr int kPackets = 4000;
  const WrittenFast w = write_fast(path, kPackets, 3);
  const std::uint64_t in_file = w.in_file;
  CHECK(w.messages == in_file);
  CHECK(in_file + w.not_recorded == kPackets);
  const std::vector<StoredChunk> chunks = chunks_in(path);
  INFO(chunks.size() << " chunks");
  std::uint64_t stored = 0;
  for (const StoredChunk& chunk : chunks) {
    INFO("compression '" << chunk.compression << "'");
    CHECK((chunk.compression == "" || chunk.compression == "zstd"));
    if (chunk.compression.empty()) {
      ++stored;
      CHECK(chunk.crc_matches);  // a stored chunk's CRC is always there
      CHECK(chunk.crc != 0);
    } else {
      CHECK(chunk.crc == 0);  // mcap_chunk_crc's default: zstd's checksum instead
    }
  }
  CHECK(w.stored > 0);
  CHECK(stored == w.stored);
  CHECK(chunks.back().compression == "zstd");  // the last chunk had none behind it
  // The next start's recovery reads the stored chunks as the compressed ones: every message.
  CHECK(finish_interrupted_mcap(path.string()).messages == in_file);
  const auto read = test::read_mcap_independently(path);
  if (read.reader_missing) return;
  INFO(read.error);
  REQUIRE(read.file);
  CHECK((*read.file)["statistics"]["message_count"] == in_file);
  CHECK((*read.file)["topics"]["/pandar/packets"]["count"] == in_file);
  const auto kinds = (*read.file)["chunk_compressions"].get<std::vector<std::string>>();
  CHECK(static_cast<std::uint64_t>(std::ranges::count(kinds, "")) == stored);
}

TEST_CASE("damage inside a chunk stored as it is: its CRC finds it and the recovery cuts there",
          "[mcap][threads]") {
  // mcap_chunk_crc is off (the default): compressed chunks say CRC 0, but a stored one always
  // has its CRC, since no codec's checksum would see a zeroed payload in it.
  test::ScratchDir dir("mcap-behind-damage");
  const fs::path path = dir / "a.mcap";
  const std::uint64_t in_file = write_fast(path, 4000, 7).in_file;
  std::string bytes = harness::read_file(path);
  const DataSection data = data_section(bytes);
  const std::vector<StoredChunk>& chunks = data.chunks;
  // A stored chunk after the first if there is one (so that the cut keeps some messages).
  const auto stored_chunk = [](const StoredChunk& c) {
    return c.compression.empty() && c.records_bytes > 4096;
  };
  auto damaged =
      std::find_if(chunks.begin() + (chunks.size() > 1 ? 1 : 0), chunks.end(), stored_chunk);
  if (damaged == chunks.end()) damaged = std::ranges::find_if(chunks, stored_chunk);
  REQUIRE(damaged != chunks.end());
  // 200 zero bytes in the middle of its records, and the file cut where its data ends (a killed
  // run's .part has no tail: with one, it would be a file finished but not yet renamed).
  bytes.resize(data.end);
  const std::size_t at = damaged->records_offset + damaged->records_bytes / 2;
  REQUIRE(bytes.substr(at, 200) != std::string(200, '\0'));
  bytes.replace(at, 200, std::string(200, '\0'));
  const fs::path part = dir / "damaged.mcap.part";
  std::ofstream(part, std::ios::binary) << bytes;
  const McapRecovery r = finish_interrupted_mcap(part.string());
  CHECK(r.ours);
  CHECK(r.kept_bytes <= damaged->offset);  // cut before the damaged chunk, nothing after it kept
  CHECK(r.messages < in_file);
  if (r.messages == 0) return;  // nothing before it: the daemon removes such a file
  const auto read = test::read_mcap_independently(part);
  if (read.reader_missing) return;
  INFO(read.error);
  REQUIRE(read.file);
  CHECK((*read.file)["statistics"]["message_count"] == r.messages);
}

TEST_CASE("a file's close hands over its last chunk: never a chunk behind", "[mcap][threads]") {
  // Files of one full chunk and a few packets more, closed at once, as a rotation by size or a
  // SIGHUP does right after a chunk fills: the close hands the open chunk over while the full
  // one may still wait for the thread. That is not compression behind, whatever the timing, for
  // every compression.
  const auto compression = GENERATE(mcap::ChunkCompression::kLz4, mcap::ChunkCompression::kZstd);
  INFO("compression '" << mcap::compression_name(compression) << "'");
  test::ScratchDir dir("mcap-close-behind");
  McapFile file(live_options(compression, 1));
  const auto payloads = wordy_bytes(1262 * 64, 5);
  for (int f = 0; f < 30; ++f) {
    const fs::path path = dir / ("f" + std::to_string(f) + ".mcap");
    file.open(path.string(), kBehindT0);
    std::uint64_t in_file = 0;
    for (int i = 0; i < 60; ++i) {  // 64 kB chunks hold 50 packets
      const std::uint64_t t = kBehindT0 + static_cast<std::uint64_t>(i) * 1000;
      const auto payload =
          std::span(payloads).subspan(static_cast<std::size_t>(i % 64) * 1262, 1262);
      in_file += file.add_packet(payload, static_cast<std::int64_t>(t), t);
    }
    file.close();
    CHECK(in_file == 60);
    const std::vector<StoredChunk> chunks = chunks_in(path);
    CHECK(chunks.size() == 2);
    for (const StoredChunk& chunk : chunks)
      CHECK(chunk.compression == mcap::compression_name(compression));
  }
  CHECK(file.chunks_uncompressed() == 0);
  CHECK(file.messages_not_recorded() == 0);
}
