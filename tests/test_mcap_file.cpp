// daemon/mcap: one MCAP file written by McapFile (its chunks compressed by the chunk pipeline's
// thread, so every test that makes one is tagged [threads]), and finish_interrupted_mcap() for a
// ".part" a killed run left, cut anywhere. Every finished or recovered file is read back by the
// MCAP project's own reader (support/mcap_reader.hpp), which must accept it whole.
#include <catch2/catch.hpp>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "bench/child_process.hpp"
#include "core/frames/pcd.hpp"
#include "core/mcap/mcap_parse.hpp"
#include "daemon/mcap/mcap_file.hpp"
#include "daemon/mcap/mcap_recovery.hpp"
#include "daemon/pcap/recording_model.hpp"
#include "support/mcap_data_records.hpp"
#include "support/mcap_reader.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
namespace fs = std::filesystem;

namespace {

constexpr std::uint64_t kT0 = 1'795'348'800'000'000'000;  // 2026-11-20, ns

// A frame of `n` points whose fields tell them apart.
struct TestFrame {
  std::vector<Point> storage;
  Frame frame;
  TestFrame(std::size_t n, std::int64_t start_ns) : storage(n) {
    for (std::size_t i = 0; i < n; ++i) {
      Point& p = storage[i];
      p.x = static_cast<float>(i) * 0.25f;
      p.y = -static_cast<float>(i);
      p.z = 1.5f;
      p.intensity = static_cast<std::uint8_t>(i);
      p.channel = static_cast<std::uint8_t>(i % 40);
      p.return_type = ReturnType::kLastStrongest;
      p.timestamp_ns = start_ns + static_cast<std::int64_t>(i) * 1000;
    }
    frame.points = storage;
    frame.size = n;
    frame.info.start_ns = start_ns;
  }
};

McapFileOptions small_options(mcap::ChunkCompression compression = mcap::ChunkCompression::kZstd) {
  McapFileOptions o;
  o.compression = compression;
  o.chunk_bytes = 64 * 1024;  // several chunks per file
  o.max_frame_points = 4000;
  o.max_chunks = 64;
  o.packets = true;
  o.library = "pandarcap test";
  o.metadata = {{"version", "test"}};
  o.calibration_csv = "Channel,Elevation,Azimuth\n1,15,0\n";
  o.sensor_model = "Pandar64";   // the packets channel's metadata (its packets name no model)
  o.wait_for_free_chunk = true;  // the files below are whole; the tests of the pool say otherwise
  return o;
}

// Frames of 3000 points (69 kB each: a chunk apiece), packets and health, flushed now and then
// as the writer's tick does. Returns the messages written.
std::uint64_t write_mcap(const fs::path& path, const McapFileOptions& options, int seconds) {
  McapFile file(options);
  file.open(path.string(), kT0);
  std::vector<std::uint8_t> packet(1262);
  for (int s = 0; s < seconds; ++s) {
    for (int f = 0; f < 3; ++f) {
      const std::uint64_t t = kT0 + s * 1'000'000'000ull + f * 100'000'000ull;
      TestFrame frame(3000, static_cast<std::int64_t>(t));
      file.add_frame(frame.frame, t);
      for (int p = 0; p < 5; ++p) {
        packet[0] = 0xEE;
        packet[1] = static_cast<std::uint8_t>(p);
        file.add_packet(packet, static_cast<std::int64_t>(t + p), t + p);
      }
    }
    file.add_health(
        R"({"state":"ok","counters":{"datagrams_received":)" + std::to_string(s) + "}}\n",
        kT0 + s * 1'000'000'000ull + 900'000'000ull);
    file.flush();
  }
  file.close();
  return file.messages();
}

std::string read_all(const fs::path& path) {
  return harness::read_file(path);
}

}  // namespace

TEST_CASE("an MCAP file is read whole by the MCAP project's reader, messages decoded",
          "[mcap][outputs][threads]") {
  const auto compression = GENERATE(mcap::ChunkCompression::kZstd, mcap::ChunkCompression::kLz4);
  const std::string name(mcap::compression_name(compression));
  INFO("compression " << name);
  test::ScratchDir dir("mcap-file-" + name);
  const fs::path path = dir / "a.mcap";
  const McapFileOptions options = small_options(compression);
  const std::uint64_t messages = write_mcap(path, options, 2);
  CHECK(messages == 2 * (3 + 15 + 1));
  const auto read = test::read_mcap_independently(path);
  if (read.reader_missing) return;
  INFO(read.error);
  REQUIRE(read.file);
  const auto& f = *read.file;
  CHECK(f["header"]["profile"] == "ros2");
  CHECK(f["header"]["library"] == "pandarcap test");
  CHECK(f["statistics"]["message_count"] == messages);
  CHECK(f["statistics"]["chunk_count"].get<int>() >= 6);  // a frame fills a 64 kB chunk
  CHECK(f["chunk_compression"] == nlohmann::json::array({name}));
  REQUIRE(f["attachments"].size() == 1);
  CHECK(f["attachments"][0]["name"] == "calibration.csv");
  CHECK(f["attachments"][0]["text"] == options.calibration_csv);
  CHECK(f["metadata"][0]["entries"]["version"] == "test");
  REQUIRE(f["channels"].size() == 3);
  CHECK(f["channels"][2]["topic"] == "/pandar/packets");
  CHECK(f["channels"][2]["metadata"] == nlohmann::json{{"sensor_model", "Pandar64"}});
  CHECK(f["channels"][0]["metadata"] == nlohmann::json::object());
  const auto& points = f["topics"]["/pandar/points"];
  CHECK(points["schema"] == "sensor_msgs/msg/PointCloud2");
  REQUIRE(points["count"] == 6);
  const auto& first = points["messages"][0];
  CHECK(first["frame_id"] == "pandar");
  CHECK(first["points"] == 3000);
  CHECK(first["width"] == 3000);
  CHECK(first["point_step"] == kPcdPointBytes);
  CHECK(first["stamp"]["sec"] == kT0 / 1'000'000'000);
  CHECK(first["last"]["x"].get<double>() == Approx(2999 * 0.25));
  CHECK(first["last"]["y"].get<double>() == Approx(-2999));
  CHECK(first["last"]["channel"] == 2999 % 40);
  CHECK(first["last"]["return_type"] == 3);
  CHECK(first["last"]["timestamp"].get<double>() ==
        Approx(static_cast<double>(kT0 + 2999 * 1000) * 1e-9));
  CHECK(first["sums"]["z"].get<double>() == Approx(3000 * 1.5));
  const auto& packets = f["topics"]["/pandar/packets"];
  CHECK(packets["schema"] == "pandar_msgs/msg/PandarPacket");
  CHECK(packets["count"] == 30);
  CHECK(packets["messages"][1]["size"] == 1262);
  CHECK(packets["messages"][1]["first_bytes"] == nlohmann::json::array({0xEE, 1}));
  const auto& health = f["topics"]["/pandar/health"];
  CHECK(health["count"] == 2);
  CHECK(health["messages"][1]["datagrams_received"] == 1);
}

TEST_CASE("a file cut anywhere is finished into one the reader accepts, keeping whole chunks",
          "[mcap][recovery][threads]") {
  const auto compression = GENERATE(mcap::ChunkCompression::kZstd, mcap::ChunkCompression::kLz4);
  const std::string name(mcap::compression_name(compression));
  INFO("compression " << name);
  test::ScratchDir dir("mcap-recovery-" + name);
  const fs::path whole = dir / "whole.mcap";
  const McapFileOptions options = small_options(compression);
  const std::uint64_t messages = write_mcap(whole, options, 3);
  const std::string bytes = read_all(whole);
  std::mt19937 rng(20261125);
  std::vector<std::uint64_t> cuts{9, 40, bytes.size() / 2, bytes.size() - 1, bytes.size() - 30};
  for (int i = 0; i < 12; ++i)
    cuts.push_back(rng() % bytes.size());
  std::uint64_t previous_kept = 0;
  for (const std::uint64_t cut : cuts) {
    INFO("cut at " << cut << " of " << bytes.size());
    const fs::path part = dir / ("cut-" + std::to_string(cut) + ".mcap.part");
    std::ofstream(part, std::ios::binary) << bytes.substr(0, cut);
    const McapRecovery r = finish_interrupted_mcap(part.string());
    CHECK(r.ours);
    CHECK(r.messages <= messages);
    CHECK(r.kept_bytes <= cut);
    CHECK(r.cut_bytes == cut - r.kept_bytes);
    if (r.messages == 0) {
      CHECK(fs::file_size(part) == cut);  // left for the caller to remove
      continue;
    }
    // Kept: exactly the bytes before the cut point, then a new tail.
    const std::string after = read_all(part);
    CHECK(after.compare(0, r.kept_bytes, bytes, 0, r.kept_bytes) == 0);
    const auto read = test::read_mcap_independently(part);
    if (read.reader_missing) continue;
    INFO(read.error);
    REQUIRE(read.file);
    CHECK((*read.file)["statistics"]["message_count"] == r.messages);
    CHECK((*read.file)["chunk_compression"] == nlohmann::json::array({name}));
    CHECK((*read.file)["attachments"][0]["name"] == "calibration.csv");
    previous_kept = std::max(previous_kept, r.kept_bytes);
  }
  CHECK(previous_kept > 0);
  // The whole file as a .part (killed after its footer, before its rename): all kept.
  const fs::path done = dir / "done.mcap.part";
  fs::copy_file(whole, done);
  const McapRecovery r = finish_interrupted_mcap(done.string());
  CHECK(r.messages == messages);
  const auto read = test::read_mcap_independently(done);
  if (!read.reader_missing) {
    INFO(read.error);
    REQUIRE(read.file);
    CHECK((*read.file)["statistics"]["message_count"] == messages);
    // The summary recovery wrote repeats the channels' metadata.
    CHECK((*read.file)["channels"][2]["metadata"] == nlohmann::json{{"sensor_model", "Pandar64"}});
  }
}

TEST_CASE("an MCAP's packets channel names its model: the replay's word when no packet names one",
          "[mcap][sensors][threads]") {
  test::ScratchDir dir("mcap-named-model");
  McapFileOptions options = small_options();
  // The packets write_file writes start EE 00..04 and are 1262 bytes: no model's.
  write_mcap(dir / "named.mcap", options, 1);
  const auto named = recording_model((dir / "named.mcap").string(), std::nullopt);
  REQUIRE(named);
  CHECK(named->from_file);
  CHECK(named->detected.kind == DetectionKind::kKnown);
  CHECK(named->detected.model == SensorModelId::kPandar64);
  CHECK(named->named == SensorModelId::kPandar64);
  CHECK(named->records == 15);  // every packet read first
  // No name (a live "auto" wrote it), or one pandarcap does not know: nothing names a model.
  for (const char* name : {"", "PandarAT128"}) {
    options.sensor_model = name;
    const fs::path path = dir / (std::string("other-") + name + ".mcap");
    write_mcap(path, options, 1);
    CHECK_FALSE(recording_model(path.string(), std::nullopt));
  }
}

TEST_CASE("recovery leaves files that are not pandarcap's MCAP alone and refuses links",
          "[mcap][recovery][threads]") {
  test::ScratchDir dir("mcap-not-ours");
  const fs::path text = dir / "notes.mcap.part";
  std::ofstream(text) << "not an MCAP file at all\n";
  CHECK_FALSE(finish_interrupted_mcap(text.string()).ours);
  CHECK(read_all(text) == "not an MCAP file at all\n");

  // Another writer's MCAP (its Header names another library): not ours to cut.
  const fs::path other = dir / "other.mcap.part";
  {
    std::vector<std::uint8_t> out;
    mcap::ByteWriter w(out);
    w.bytes(mcap::kMagic);
    mcap::write_header(w, "ros2", "rosbag2");
    w.bytes(std::string_view("trailing bytes of a cut record"));
    std::ofstream(other, std::ios::binary)
        .write(reinterpret_cast<const char*>(out.data()), static_cast<std::streamsize>(out.size()));
  }
  const std::string before = read_all(other);
  CHECK_FALSE(finish_interrupted_mcap(other.string()).ours);
  CHECK(read_all(other) == before);

  // A link to a file of ours: refused, and its target untouched.
  const fs::path target = dir / "target.mcap";
  write_mcap(target, small_options(), 1);
  const std::string target_bytes = read_all(target);
  const fs::path link = dir / "link.mcap.part";
  fs::create_symlink(target, link);
  CHECK_THROWS(finish_interrupted_mcap(link.string()));
  CHECK(read_all(target) == target_bytes);
}

TEST_CASE("a damaged chunk ends what is kept: nothing after it is trusted",
          "[mcap][recovery][threads]") {
  test::ScratchDir dir("mcap-damaged");
  const fs::path whole = dir / "whole.mcap";
  const std::uint64_t messages = write_mcap(whole, small_options(), 2);
  std::string bytes = read_all(whole);
  // The second half of the file flipped: its chunks no longer decompress or match their CRC.
  for (std::size_t i = bytes.size() / 2; i < bytes.size(); i += 97)
    bytes[i] ^= 0x5A;
  const fs::path part = dir / "damaged.mcap.part";
  std::ofstream(part, std::ios::binary) << bytes;
  const McapRecovery r = finish_interrupted_mcap(part.string());
  CHECK(r.ours);
  CHECK(r.messages > 0);
  CHECK(r.messages < messages);
  const auto read = test::read_mcap_independently(part);
  if (read.reader_missing) return;
  INFO(read.error);
  REQUIRE(read.file);
  CHECK((*read.file)["statistics"]["message_count"] == r.messages);
}

TEST_CASE(
    "one flipped bit in a chunk: found by the CRC with mcap_chunk_crc on, by zstd's checksum with "
    "it off (the default: every chunk's CRC 0)",
    "[mcap][recovery][threads]") {
  const auto compression = GENERATE(mcap::ChunkCompression::kLz4, mcap::ChunkCompression::kZstd,
                                    mcap::ChunkCompression::kNone);
  const bool chunk_crc = GENERATE(false, true);
  const std::string name(mcap::compression_name(compression));
  INFO("compression '" << name << "', chunk_crc " << chunk_crc);
  test::ScratchDir dir("mcap-bit-flip");
  const fs::path whole = dir / "whole.mcap";
  McapFileOptions options = small_options(compression);
  options.chunk_crc = chunk_crc;
  const std::uint64_t messages = write_mcap(whole, options, 2);
  std::string bytes = read_all(whole);
  const std::span<const std::uint8_t> file(reinterpret_cast<const std::uint8_t*>(bytes.data()),
                                           bytes.size());
  // The chunks' CRCs as asked: computed with the key on, 0 ("not computed") with it off.
  std::vector<std::pair<std::size_t, std::size_t>> stored;  // each chunk's records: at, size
  for (const test::DataRecord& record : test::data_records(file)) {
    if (record.op != mcap::Op::kChunk) continue;
    const auto chunk = mcap::parse_chunk(record.content);
    REQUIRE(chunk);
    CHECK((chunk->uncompressed_crc != 0) == chunk_crc);
    stored.emplace_back(static_cast<std::size_t>(chunk->records.data() - file.data()),
                        chunk->records.size());
  }
  REQUIRE(stored.size() >= 4);
  // One bit in the middle of the third chunk's stored records: a literal that still decodes
  // (lz4, none) is caught only by a checksum.
  const auto [at, size] = stored[2];
  bytes[at + size / 2] = static_cast<char>(bytes[at + size / 2] ^ 0x01);
  const fs::path part = dir / "damaged.mcap.part";
  std::ofstream(part, std::ios::binary) << bytes;
  const McapRecovery r = finish_interrupted_mcap(part.string());
  CHECK(r.ours);
  CHECK(r.messages > 0);  // the chunks before it are kept
  // lz4 and uncompressed chunks without a CRC have no checksum: a flipped literal is not seen
  // (docs/mcap.md says so); every other case finds it.
  if (chunk_crc || compression == mcap::ChunkCompression::kZstd) {
    CHECK(r.messages < messages);  // the damaged one (and what follows) is not
    CHECK(r.kept_bytes <= at);
  }
}

TEST_CASE("McapFile::abandon cuts back to the last whole chunk", "[mcap][recovery][threads]") {
  test::ScratchDir dir("mcap-abandon");
  const fs::path path = dir / "a.mcap.part";
  McapFile file(small_options());
  file.open(path.string(), kT0);
  TestFrame frame(3000, static_cast<std::int64_t>(kT0));
  file.add_frame(frame.frame, kT0);
  file.flush();  // handed to the compression thread
  file.drain();  // and written
  const auto flushed = fs::file_size(path);
  file.add_health(R"({"state":"ok"})", kT0 + 1);  // in the open chunk, not on disk
  CHECK(file.abandon() == 1);
  CHECK(fs::file_size(path) == flushed);
  const McapRecovery r = finish_interrupted_mcap(path.string());
  CHECK(r.messages == 1);
  CHECK(r.cut_bytes == 0);
}

TEST_CASE("no free chunk buffer: the message is left out and counted, never waited for",
          "[mcap][threads]") {
  test::ScratchDir dir("mcap-pool-full");
  const fs::path path = dir / "a.mcap";
  McapFileOptions options = small_options();
  options.chunk_buffers = 1;
  options.wait_for_free_chunk = false;  // live: never wait
  McapFile file(options);
  file.open(path.string(), kT0);
  TestFrame frame(3000, static_cast<std::int64_t>(kT0));  // 69 kB: over a 64 kB chunk
  CHECK(file.add_frame(frame.frame, kT0));
  // The next message hands the full chunk over, and the only buffer is then in flight: it comes
  // back only when this thread picks it up, at the next message at the earliest, so this
  // message has no chunk to go to.
  CHECK_FALSE(file.add_frame(frame.frame, kT0 + 100'000'000));
  CHECK(file.messages_not_recorded() == 1);
  file.close();
  CHECK(file.messages() == 1);
  CHECK(file.messages_not_recorded() == 1);
  const McapRecovery r = finish_interrupted_mcap(path.string());  // a finished file: all kept
  CHECK(r.messages == 1);
  const auto read = test::read_mcap_independently(path);
  if (read.reader_missing) return;
  INFO(read.error);
  REQUIRE(read.file);
  CHECK((*read.file)["statistics"]["message_count"] == 1);
}

TEST_CASE("close drains the chunk pipeline: every chunk handed over is in the file",
          "[mcap][threads]") {
  const auto compression = GENERATE(mcap::ChunkCompression::kZstd, mcap::ChunkCompression::kLz4,
                                    mcap::ChunkCompression::kNone);
  const std::string name(mcap::compression_name(compression));
  INFO("compression '" << name << "'");
  test::ScratchDir dir("mcap-drain");
  const fs::path path = dir / "a.mcap";
  McapFileOptions options = small_options(compression);
  options.chunk_buffers = 8;  // more than the chunks below: none is ever left out
  McapFile file(options);
  file.open(path.string(), kT0);
  // Five frames, a chunk each, handed over one after the other without any wait; close()
  // then finds most of them still in flight.
  for (int f = 0; f < 5; ++f) {
    const std::uint64_t t = kT0 + f * 100'000'000ull;
    TestFrame frame(3000, static_cast<std::int64_t>(t));
    REQUIRE(file.add_frame(frame.frame, t));
  }
  file.close();
  CHECK(file.messages() == 5);
  CHECK(file.messages_not_recorded() == 0);
  const auto read = test::read_mcap_independently(path);
  if (read.reader_missing) return;
  INFO(read.error);
  REQUIRE(read.file);
  CHECK((*read.file)["statistics"]["message_count"] == 5);
  CHECK((*read.file)["statistics"]["chunk_count"] == 5);
  CHECK((*read.file)["topics"]["/pandar/points"]["count"] == 5);
}

TEST_CASE("writer and compression thread: every message written or counted, files whole",
          "[mcap][threads]") {
  // Two buffers and small chunks, so the writer often finds both in flight: messages are left
  // out (counted) while the compression thread works, in any interleaving. Run under TSan in CI.
  test::ScratchDir dir("mcap-threads");
  McapFileOptions options = small_options(mcap::ChunkCompression::kZstd);
  options.chunk_buffers = 2;
  options.wait_for_free_chunk = false;
  options.chunk_bytes = 16 * 1024;
  options.max_chunks = 4096;
  McapFile file(options);
  std::vector<std::uint8_t> packet(1262, 0xAB);
  std::uint64_t handed = 0, recorded = 0, written = 0;
  for (int n = 0; n < 3; ++n) {
    const fs::path path = dir / ("f" + std::to_string(n) + ".mcap");
    file.open(path.string(), kT0);
    const std::uint64_t not_recorded_before = file.messages_not_recorded();
    std::uint64_t in_file = 0;
    for (int i = 0; i < 3000; ++i) {
      const std::uint64_t t = kT0 + static_cast<std::uint64_t>(i) * 1000;
      packet[0] = static_cast<std::uint8_t>(i);
      ++handed;
      in_file += file.add_packet(packet, static_cast<std::int64_t>(t), t);
      if (i % 700 == 0) file.flush();
    }
    file.close();
    CHECK(file.messages() == in_file);
    CHECK(in_file + (file.messages_not_recorded() - not_recorded_before) == 3000);
    recorded += in_file;
    written += file.messages();
    const McapRecovery r = finish_interrupted_mcap(path.string());
    CHECK(r.messages == in_file);
  }
  CHECK(written == recorded);
  CHECK(recorded + file.messages_not_recorded() == handed);
}

TEST_CASE("a replay waits for a chunk buffer instead: every message is written",
          "[mcap][threads]") {
  test::ScratchDir dir("mcap-pool-wait");
  const fs::path path = dir / "a.mcap";
  McapFileOptions options = small_options();
  options.chunk_buffers = 1;  // every second frame finds the only buffer in flight
  McapFile file(options);
  file.open(path.string(), kT0);
  for (int f = 0; f < 6; ++f) {
    const std::uint64_t t = kT0 + f * 100'000'000ull;
    TestFrame frame(3000, static_cast<std::int64_t>(t));
    CHECK(file.add_frame(frame.frame, t));
  }
  file.close();
  CHECK(file.messages() == 6);
  CHECK(file.messages_not_recorded() == 0);
  CHECK(finish_interrupted_mcap(path.string()).messages == 6);
}
