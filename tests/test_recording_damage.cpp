// Recordings that say when they are damaged: a matrix of damage kinds x positions x formats
// (pcap, pcap.zst with zstd's content checksum, MCAP with zstd, lz4 and uncompressed chunks),
// read as the replay reads them (CaptureReader, in-process: cheap). Each damaged file is caught
// and named: it cannot be opened, or it ends in kError / kTruncated, or it is read over with the
// damage counted and named; never a clean kEnd that replays wrong packets as if whole. Then the
// daemon and pandarcap-inspect on one damaged file of each kind: the exit status (65, 1), the
// summary and the last health record (degraded, naming the damage; never "ok").
#include <catch2/catch.hpp>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "bench/child_process.hpp"
#include "core/mcap/mcap_records.hpp"
#include "daemon/pcap/capture_reader.hpp"
#include "daemon/pcap/pcap_writer.hpp"
#include "daemon/pcap/zstd_write_stream.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
namespace fs = std::filesystem;
using test::quoted;
using test::write_bytes;

namespace {

constexpr std::int64_t kDamageRecordedNs = 1'677'657'600'000'000'000;  // 2023-03-01T08:00:00Z
constexpr int kDamagePackets = 1800;  // half a second of a dual-return sensor
constexpr Endpoint kDamageLidar{0xC0A801C9, 2368};
constexpr Endpoint kDamageHost{0xC0A8010A, 2368};

struct Outcome {
  bool opened = false;
  std::string open_error;
  CaptureStatus status = CaptureStatus::kEnd;
  std::string error, first_damage;
  CaptureStats stats;
  std::vector<std::vector<std::uint8_t>> payloads;

  // What the replay and pandarcap-inspect call whole: read to a clean end, nothing read over.
  bool whole() const {
    return opened && status == CaptureStatus::kEnd && first_damage.empty() && stats.malformed == 0;
  }
  // The text that names the damage (the open error, the end's, or the first read over).
  std::string named() const { return !opened ? open_error : !error.empty() ? error : first_damage; }
};

Outcome read_file(const fs::path& file) {
  Outcome o;
  try {
    CaptureReader reader(file.string());
    o.opened = true;
    CaptureRecord record;
    while ((o.status = reader.next(record)) == CaptureStatus::kRecord)
      o.payloads.emplace_back(record.payload.begin(), record.payload.end());
    o.error = reader.error();
    o.first_damage = reader.first_damage();
    o.stats = reader.stats();
  } catch (const CaptureError& e) {
    o.open_error = e.what();
  }
  return o;
}

// Caught and named: not whole, and the file's name in what says so.
void check_caught(const Outcome& o, const fs::path& file) {
  CHECK_FALSE(o.whole());
  const std::string named = o.named();
  INFO("named: " << named);
  CHECK(named.find(file.filename().string()) != std::string::npos);
}

std::string flip(std::string bytes, std::size_t at, std::size_t n) {
  for (std::size_t i = at; i < at + n && i < bytes.size(); ++i)
    bytes[i] = static_cast<char>(bytes[i] ^ 0xFF);
  return bytes;
}

// The recording as pandarcapd compresses it: one zstd frame with its content checksum.
std::string compress_as_recorder(const std::string& pcap) {
  ZstdStreamCompressor compressor(pcap.size(), 1);
  const auto out =
      compressor.compress({reinterpret_cast<const std::uint8_t*>(pcap.data()), pcap.size()},
                          ZstdStreamCompressor::Step::kEnd);
  return {reinterpret_cast<const char*>(out.data()), out.size()};
}

// The top-level chunks of an MCAP file, each with the packets its message index lists (those
// of the channel on topic /pandar/packets).
struct Chunk {
  std::size_t at = 0;
  std::uint64_t length = 0;  // the record's content
  std::uint64_t packets = 0;
};
std::vector<Chunk> mcap_chunks(const std::string& bytes) {
  std::vector<Chunk> chunks;
  std::uint16_t packets_channel = 0;
  for (std::size_t at = mcap::kMagic.size(); at + 9 <= bytes.size();) {
    std::uint64_t length = 0;
    std::memcpy(&length, bytes.data() + at + 1, 8);
    const auto op = static_cast<mcap::Op>(bytes[at]);
    const auto content = std::span(reinterpret_cast<const std::uint8_t*>(bytes.data()) + at + 9,
                                   static_cast<std::size_t>(length));
    if (op == mcap::Op::kDataEnd) break;
    if (op == mcap::Op::kChannel) {
      mcap::ByteReader r(content);
      const std::uint16_t id = r.u16();
      r.u16();
      if (r.string() == "/pandar/packets") packets_channel = id;
    }
    if (op == mcap::Op::kChunk) chunks.push_back({at, length, 0});
    if (op == mcap::Op::kMessageIndex && !chunks.empty()) {
      mcap::ByteReader r(content);
      if (r.u16() == packets_channel) chunks.back().packets += r.u32() / 16;
    }
    at += 9 + length;
  }
  return chunks;
}

fs::path convert_to_mcap(const fs::path& capture, const fs::path& dir,
                         const std::string& compression) {
  // Small chunks, so that a damaged one is a small part of the file and several follow it.
  // zstd as by default (no chunk CRC: zstd's checksum finds a flipped bit); lz4 and none have no
  // checksum of their own, so their chunks carry the CRC (output.mcap_chunk_crc, docs/mcap.md).
  fs::create_directories(dir);
  std::ofstream(dir / "chunks.toml") << "[output]\nmcap_chunk_bytes = 262144\n"
                                     << (compression == "zstd" ? "" : "mcap_chunk_crc = true\n");
  const auto r = test::run_command(test::pandarcapd_command() + " -c " +
                                   quoted(dir / "chunks.toml") + " --replay " + quoted(capture) +
                                   " --mcap-only --mcap-packets --mcap-compression " + compression +
                                   " --output-dir " + quoted(dir) + " 2>&1");
  INFO(r.out);
  REQUIRE(r.exit_code == 0);
  const auto files = test::files_ending(dir / "mcap", ".mcap");
  REQUIRE(files.size() == 1);
  return files.front();
}

}  // namespace

TEST_CASE("a damaged pcap is caught and named, header by header", "[capture][damage]") {
  test::ScratchDir dir("damage-pcap");
  const fs::path pcap = test::write_simulated_recording(
      dir / "whole.pcap", kDamagePackets, kDamageRecordedNs, kDamageLidar, kDamageHost);
  const std::string bytes = harness::read_file(pcap);
  const Outcome whole = read_file(pcap);
  REQUIRE(whole.whole());
  REQUIRE(whole.payloads.size() == kDamagePackets);

  // The global header: magic, version, link type: the file cannot be opened, and says which.
  for (const auto& [field, at] : std::vector<std::pair<const char*, std::size_t>>{
           {"magic", 0}, {"version", 4}, {"link type", 20}}) {
    INFO("global header " << field);
    const fs::path file = dir / (std::string("global-") + std::to_string(at) + ".pcap");
    write_bytes(file, flip(bytes, at, 2));
    const Outcome o = read_file(file);
    CHECK_FALSE(o.opened);
    check_caught(o, file);
  }
  // A record's header: ts_usec (its high byte), caplen and len (low and high bytes), in the
  // first, a middle and the last record. Uncompressed pcap has no checksum: its packets' bytes
  // are not checked, but every header field that no capture tool writes is.
  for (const std::size_t record :
       {std::size_t{0}, std::size_t{kDamagePackets / 2}, std::size_t{kDamagePackets - 1}}) {
    const std::size_t header = test::pcap_record_offset(bytes, record);
    for (const auto& [field, offset] :
         std::vector<std::pair<const char*, std::size_t>>{{"ts_usec high byte", 7},
                                                          {"caplen low byte", 8},
                                                          {"caplen high byte", 10},
                                                          {"len low byte", 12},
                                                          {"len high byte", 13}}) {
      INFO("record " << record << " " << field);
      const fs::path file =
          dir / ("record-" + std::to_string(record) + "-" + std::to_string(offset) + ".pcap");
      write_bytes(file, flip(bytes, header + offset, 1));
      const Outcome o = read_file(file);
      REQUIRE(o.opened);
      // Every record before the damaged one is read as it was.
      REQUIRE(o.payloads.size() >= record);
      for (std::size_t i = 0; i < record; ++i)
        REQUIRE(o.payloads[i] == whole.payloads[i]);
      check_caught(o, file);
    }
  }
  // Cut inside a record: kTruncated, "cut off".
  const fs::path cut = dir / "cut.pcap";
  write_bytes(cut, bytes.substr(0, test::pcap_record_offset(bytes, kDamagePackets / 2) + 100));
  const Outcome o = read_file(cut);
  CHECK(o.status == CaptureStatus::kTruncated);
  CHECK(o.payloads.size() == kDamagePackets / 2);
  check_caught(o, cut);
}

TEST_CASE("a damaged pcap.zst is caught by zstd, its checksum included",
          "[capture][damage][zstd]") {
  test::ScratchDir dir("damage-pcap-zst");
  const fs::path pcap = test::write_simulated_recording(
      dir / "whole.pcap", kDamagePackets, kDamageRecordedNs, kDamageLidar, kDamageHost);
  const Outcome whole = read_file(pcap);
  const std::string zst = compress_as_recorder(harness::read_file(pcap));
  write_bytes(dir / "whole.pcap.zst", zst);
  REQUIRE(read_file(dir / "whole.pcap.zst").whole());
  // The frame carries the content checksum (frame header descriptor, bit 2), as `zstd -lv` shows.
  REQUIRE((static_cast<std::uint8_t>(zst[4]) & 0x04) != 0);

  struct Position {
    const char* name;
    std::size_t at;
  };
  const std::vector<Position> positions = {{"frame header descriptor", 4},
                                           {"first block", zst.size() / 20},
                                           {"middle", zst.size() / 2},
                                           {"last block", zst.size() - 40},
                                           {"content checksum", zst.size() - 4}};
  for (const Position& position : positions) {
    for (const char* kind : {"16 bytes flipped", "one bit flipped", "cut"}) {
      INFO(position.name << ": " << kind);
      const fs::path file =
          dir / (std::string("damaged-") + std::to_string(position.at) + kind[0] + ".pcap.zst");
      std::string damaged = zst;
      if (kind[0] == '1') {
        damaged = flip(zst, position.at, std::min<std::size_t>(16, zst.size() - position.at));
      } else if (kind[0] == 'o') {
        damaged[position.at] = static_cast<char>(damaged[position.at] ^ 0x08);
      } else {
        damaged.resize(position.at);
      }
      write_bytes(file, damaged);
      const Outcome o = read_file(file);
      check_caught(o, file);
      if (kind[0] == 'c' && o.opened) {
        CHECK(o.status == CaptureStatus::kTruncated);
        CHECK(o.error.find("cut short") != std::string::npos);
      } else if (o.opened) {
        // Damage, never "cut off" (the frame ends where it should); a checksum that does not
        // match says so.
        CHECK(o.status == CaptureStatus::kError);
        if (position.at == zst.size() - 4)
          CHECK(o.error.find("content checksum does not match") != std::string::npos);
      }
    }
  }
}

TEST_CASE("a damaged MCAP chunk is skipped by the chunk index, the rest read",
          "[capture][damage][mcap][threads]") {
  test::ScratchDir dir("damage-mcap");
  const fs::path pcap = test::write_simulated_recording(
      dir / "whole.pcap", kDamagePackets, kDamageRecordedNs, kDamageLidar, kDamageHost);
  for (const std::string compression : {"zstd", "lz4", "none"}) {
    const fs::path mcap = convert_to_mcap(pcap, dir / compression, compression);
    const std::string bytes = harness::read_file(mcap);
    const Outcome whole = read_file(mcap);
    REQUIRE(whole.whole());
    REQUIRE(whole.payloads.size() == kDamagePackets);
    const auto chunks = mcap_chunks(bytes);
    REQUIRE(chunks.size() >= 5);
    // The first and a middle chunk that hold packets (others hold a frame's points), and the
    // last chunk of all, after which there is none to go on at.
    std::vector<std::size_t> with_packets;
    for (std::size_t i = 0; i < chunks.size(); ++i)
      if (chunks[i].packets > 0) with_packets.push_back(i);
    REQUIRE(with_packets.size() >= 3);
    for (const std::size_t c :
         {with_packets.front(), with_packets[with_packets.size() / 2], chunks.size() - 1}) {
      const std::size_t at = chunks[c].at;
      const std::uint64_t length = chunks[c].length;
      const bool last = c == chunks.size() - 1;
      const char* const kinds[] = {"records flipped", "length absurd", "length into what follows",
                                   "opcode"};
      for (int k = 0; k < 4; ++k) {
        // A slow build (sanitizers, emulation) checks the damage to a chunk's framing (its
        // length, its opcode), which the chunk index mends the same way whatever the chunk
        // holds, on one compression; the damage inside its records, which each codec meets in
        // its own way, on all three. Every copy of the file costs there (36 of them took 44 s
        // under TSan); release checks every case.
        if (test::kSlowBuild && k != 0 && compression != "none") continue;
        const std::string kind = kinds[k];
        INFO(compression << " chunk " << c << " of " << chunks.size() << ": " << kind);
        std::string damaged = bytes;
        if (k == 0) {
          damaged = flip(bytes, at + 9 + length / 2, 16);  // inside its records: CRC or codec
        } else if (k == 1 || k == 2) {
          const std::uint64_t claimed = k == 1 ? std::uint64_t{1} << 50 : length + 64;
          std::memcpy(damaged.data() + at + 1, &claimed, 8);
        } else {
          damaged[at] = 0x42;  // an opcode MCAP does not have
        }
        const fs::path file = dir / compression /
                              ("damaged-" + std::to_string(c) + "-" + std::to_string(k) + ".mcap");
        write_bytes(file, damaged);
        const Outcome o = read_file(file);
        check_caught(o, file);
        // Truthful: damage, never "cut off while recording" (the file has its footer).
        CHECK(o.named().find("cut off") == std::string::npos);
        if (k == 1 || k == 2) {
          // A chunk's length is in the index too: read with the index's, nothing lost.
          CHECK(o.status == CaptureStatus::kEnd);
          CHECK(o.stats.records_damaged == 1);
          CHECK(o.stats.chunks_skipped == 0);
          CHECK(o.payloads == whole.payloads);
          CHECK(o.first_damage.find("a damaged length") != std::string::npos);
        } else if (!last) {
          // Skipped: the packets read and the packets the skipped chunk held are the file's,
          // in order, less the skipped chunk's.
          CHECK(o.status == CaptureStatus::kEnd);
          CHECK(o.stats.chunks_skipped == 1);
          CHECK(o.stats.packets_skipped == chunks[c].packets);
          CHECK(o.payloads.size() + o.stats.packets_skipped == kDamagePackets);
          std::size_t i = 0, j = 0;
          while (i < o.payloads.size() && o.payloads[i] == whole.payloads[j])
            ++i, ++j;
          j += o.stats.packets_skipped;
          while (i < o.payloads.size() && j < whole.payloads.size() &&
                 o.payloads[i] == whole.payloads[j])
            ++i, ++j;
          CHECK(i == o.payloads.size());
        } else {
          // No chunk after it to go on at: the end, as damage; everything before it read.
          CHECK(o.status == CaptureStatus::kError);
          CHECK(o.payloads.size() == kDamagePackets - chunks[c].packets);
        }
      }
    }
    // Cut (no footer): every packet before the cut, kTruncated, "cut off while recording".
    const fs::path cut = dir / compression / "cut.mcap";
    write_bytes(cut, bytes.substr(0, chunks[chunks.size() / 2].at + 100));
    const Outcome o = read_file(cut);
    CHECK(o.status == CaptureStatus::kTruncated);
    CHECK(o.error.find("cut off while recording") != std::string::npos);
    CHECK(o.payloads.size() > 0);
  }
}

TEST_CASE("a replay that met damage exits 65 and never ends ok, inspect exits 1",
          "[daemon][replay][damage][threads]") {
  test::ScratchDir dir("damage-replay");
  const fs::path pcap = test::write_simulated_recording(
      dir / "whole.pcap", kDamagePackets, kDamageRecordedNs, kDamageLidar, kDamageHost);
  const std::string zst = compress_as_recorder(harness::read_file(pcap));
  write_bytes(dir / "flipped.pcap.zst", flip(zst, zst.size() / 2, 16));
  const fs::path mcap = convert_to_mcap(pcap, dir / "convert", "zstd");
  const std::string mcap_bytes = harness::read_file(mcap);
  const auto chunks = mcap_chunks(mcap_bytes);
  std::size_t damaged_chunk = 0;
  while (damaged_chunk + 1 < chunks.size() && chunks[damaged_chunk].packets == 0)
    ++damaged_chunk;
  REQUIRE(damaged_chunk + 1 < chunks.size());
  const Chunk& chunk = chunks[damaged_chunk];
  write_bytes(dir / "chunk.mcap", flip(mcap_bytes, chunk.at + 9 + chunk.length / 2, 16));
  write_bytes(dir / "cut.pcap.zst", zst.substr(0, zst.size() / 2));

  for (const char* name : {"flipped.pcap.zst", "chunk.mcap", "cut.pcap.zst"}) {
    INFO(name);
    const fs::path out = dir / (std::string("out-") + name);
    const auto run =
        test::run_command(test::pandarcapd_command() + " --replay " + quoted(dir / name) +
                          " --output-dir " + quoted(out) + " 2>&1");
    INFO(run.out);
    CHECK(run.exit_code == 65);
    CHECK(run.out.find(std::string("replay: ") + (dir / name).string() + " is ") !=
          std::string::npos);
    CHECK(run.out.find("final health: state degraded") != std::string::npos);
    const nlohmann::json last = test::last_health_record(out);
    CHECK(last.at("state") == "degraded");
    const std::string reason = last.at("reason");
    CHECK(reason.find(name) != std::string::npos);
    CHECK(reason.find(name[0] == 'c' && name[1] == 'u' ? "recording cut short"
                                                       : "recording damaged") != std::string::npos);
    if (name[0] == 'c' && name[1] == 'h') {
      CHECK(reason.find("1 damaged chunk skipped, " + std::to_string(chunk.packets) +
                        " packets in them") != std::string::npos);
      CHECK(run.out.find("1 damaged MCAP chunks skipped") != std::string::npos);
    }
    const auto inspect = test::run_command(test::binary("pandarcap-inspect").string() +
                                           " --summary " + quoted(dir / name) + " 2>&1");
    INFO(inspect.out);
    CHECK(inspect.exit_code == 1);
    CHECK(inspect.out.find("is not whole") != std::string::npos);
  }
}
