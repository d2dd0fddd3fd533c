// Replay from every recording pandarcapd writes: a capture (pcap), the same compressed with zstd
// (raw/NAME.pcap.zst, or `zstd FILE.pcap`) and an MCAP file with its packets (--mcap-packets).
// The three give byte-identical frames and the same pandarcap-inspect summary; a cut .pcap.zst
// (a killed run's .part) gives every record before the cut and says it was cut; what cannot be
// read says so clearly.
#include <zstd.h>

#include <catch2/catch.hpp>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "bench/child_process.hpp"
#include "core/mcap/mcap_records.hpp"
#include "core/sim/synthetic_sensor.hpp"
#include "daemon/pcap/capture_reader.hpp"
#include "daemon/pcap/mcap_packet_reader.hpp"
#include "daemon/pcap/pcap_writer.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
using nlohmann::json;
namespace fs = std::filesystem;
using test::quoted;
using test::write_bytes;

namespace {

constexpr std::int64_t kRecordedNs = 1'677'657'600'000'000'000;  // 2023-03-01T08:00:00Z
constexpr int kPackets = 3600;  // one second of a dual-return sensor at 600 RPM
constexpr Endpoint kRecordingsLidar{0xC0A801C9, 2368};
constexpr Endpoint kRecordingsHost{0xC0A8010A, 2368};

fs::path simulated_capture(const fs::path& path) {
  return test::write_simulated_recording(path, kPackets, kRecordedNs, kRecordingsLidar,
                                         kRecordingsHost);
}

// `zstd -1`, as an operator compresses a capture.
fs::path zstd_command(const fs::path& pcap, const fs::path& out) {
  const auto r = test::run_command("zstd -q -1 -f -c " + quoted(pcap) + " > " + quoted(out));
  REQUIRE(r.exit_code == 0);
  return out;
}

// pandarcapd's own conversion: the capture's packets (and frames) into an MCAP file.
fs::path to_mcap(const fs::path& capture, const fs::path& dir, const std::string& extra = {},
                 bool packets = true) {
  const auto r = test::run_command(test::pandarcapd_command() + " --replay " + quoted(capture) +
                                   " --mcap-only " + (packets ? "--mcap-packets " : "") + extra +
                                   " --output-dir " + quoted(dir) + " 2>&1");
  INFO(r.out);
  REQUIRE(r.exit_code == 0);
  const auto files = test::files_ending(dir / "mcap", ".mcap");
  REQUIRE(files.size() == 1);
  return files.front();
}

struct Record {
  std::vector<std::uint8_t> payload;
  std::int64_t time_ns;
};

struct Read {
  CaptureStatus status;
  std::string error;
  std::vector<Record> records;
};

Read read_recording(const fs::path& file) {
  CaptureReader reader(file.string());
  Read r;
  CaptureRecord record;
  while ((r.status = reader.next(record)) == CaptureStatus::kRecord) {
    r.records.push_back({{record.payload.begin(), record.payload.end()}, record.timestamp_ns});
  }
  r.error = reader.error();
  return r;
}

// A replay's frames: each PCD file's name and bytes.
std::map<std::string, std::string> replay_frames(const fs::path& input, const fs::path& out,
                                                 const std::string& extra = {}) {
  const auto r = test::run_command(test::pandarcapd_command() + " --replay " + quoted(input) + " " +
                                   extra + " --output-dir " + quoted(out) + " 2>&1");
  INFO(input.filename() << ":\n" << r.out);
  REQUIRE(r.exit_code == 0);
  std::map<std::string, std::string> frames;
  for (const fs::path& pcd : test::files_ending(out / "frames", ".pcd"))
    frames[pcd.filename().string()] = harness::read_file(pcd);
  return frames;
}

json inspect_summary(const fs::path& input, const std::string& extra = {}) {
  const auto r = test::run_command(test::binary("pandarcap-inspect").string() +
                                   " --json --summary " + extra + " " + quoted(input));
  INFO(r.out);
  REQUIRE(r.exit_code == 0);
  const json j = json::parse(r.out, nullptr, false);
  REQUIRE_FALSE(j.is_discarded());
  return j.at("summary");
}

// The three recordings of one capture replay to the same frames, and inspect alike.
void check_round_trip(const fs::path& pcap, const fs::path& dir, const std::string& extra) {
  const fs::path zst = zstd_command(pcap, dir / "capture.pcap.zst");
  const fs::path mcap = to_mcap(pcap, dir / "convert", extra);
  // The same with lz4 chunks (the LZ4 frame format): read as the zstd ones are.
  const fs::path mcap_lz4 = to_mcap(pcap, dir / "convert-lz4", extra + " --mcap-compression lz4");

  // The readers: the same payloads at the same times, in the same order.
  const Read from_pcap = read_recording(pcap);
  REQUIRE(from_pcap.status == CaptureStatus::kEnd);
  REQUIRE_FALSE(from_pcap.records.empty());
  for (const fs::path& file : {zst, mcap, mcap_lz4}) {
    INFO(file.filename());
    const Read r = read_recording(file);
    CHECK(r.status == CaptureStatus::kEnd);
    CHECK(r.error.empty());
    REQUIRE(r.records.size() == from_pcap.records.size());
    for (std::size_t i = 0; i < r.records.size(); ++i) {
      REQUIRE(r.records[i].payload == from_pcap.records[i].payload);
      REQUIRE(r.records[i].time_ns == from_pcap.records[i].time_ns);
    }
  }
  CHECK(CaptureReader(zst.string()).format() == CaptureFormat::kPcapZstd);
  CHECK(CaptureReader(mcap.string()).format() == CaptureFormat::kMcap);

  // The daemon: byte-identical PCD files.
  const auto frames = replay_frames(pcap, dir / "out-pcap", extra);
  REQUIRE(frames.size() >= 3);
  CHECK(replay_frames(zst, dir / "out-zst", extra) == frames);
  CHECK(replay_frames(mcap, dir / "out-mcap", extra) == frames);
  CHECK(replay_frames(mcap_lz4, dir / "out-mcap-lz4", extra) == frames);

  // pandarcap-inspect: the same summary.
  const json s = inspect_summary(pcap, extra);
  CHECK(s.at("accepted").get<std::uint64_t>() == from_pcap.records.size());
  for (const fs::path& file : {zst, mcap}) {
    INFO(file.filename());
    const json t = inspect_summary(file, extra);
    CHECK(t.at("capture_status") == "end");
    for (const char* key : {"packets", "accepted", "rejected", "points", "frames_complete",
                            "frames_partial", "points_per_complete_frame"}) {
      CHECK(t.at(key) == s.at(key));
    }
  }
  CHECK(inspect_summary(zst, extra).at("capture_format") == "pcap.zst");
  CHECK(inspect_summary(mcap, extra).at("capture_format") == "mcap");
}

// A killed recorder's file: the capture streamed into one zstd frame, flushed after the global
// header and `records` records (as the recorder flushes every second), never ended.
std::string unfinished_zstd(const std::string& pcap, std::size_t records) {
  const std::size_t cut = test::pcap_record_offset(pcap, records);
  ZSTD_CCtx* cctx = ZSTD_createCCtx();
  ZSTD_CCtx_setParameter(cctx, ZSTD_c_compressionLevel, 3);
  std::string out(ZSTD_compressBound(cut) + 1024, '\0');
  ZSTD_outBuffer output{out.data(), out.size(), 0};
  ZSTD_inBuffer input{pcap.data(), cut, 0};
  std::size_t left = 0;
  do {
    left = ZSTD_compressStream2(cctx, &output, &input, ZSTD_e_flush);
    REQUIRE_FALSE(ZSTD_isError(left));
  } while (left != 0);
  ZSTD_freeCCtx(cctx);
  out.resize(output.pos);
  return out;
}

// The top-level records of an MCAP file: (offset, opcode).
std::vector<std::pair<std::size_t, std::uint8_t>> mcap_records(const std::string& bytes) {
  std::vector<std::pair<std::size_t, std::uint8_t>> records;
  for (std::size_t at = mcap::kMagic.size(); at + 9 <= bytes.size();) {
    std::uint64_t length = 0;
    std::memcpy(&length, bytes.data() + at + 1, 8);
    records.emplace_back(at, static_cast<std::uint8_t>(bytes[at]));
    at += 9 + length;
  }
  return records;
}

}  // namespace

TEST_CASE("replay from pcap, pcap.zst and MCAP: the same frames, byte for byte (simulated)",
          "[daemon][replay][mcap][threads]") {
  test::ScratchDir dir("replay-recordings-sim");
  const fs::path pcap = simulated_capture(dir / "capture.pcap");
  check_round_trip(pcap, dir.path(), "");
}

TEST_CASE("replay from pcap, pcap.zst and MCAP: the same frames, byte for byte (real capture)",
          "[daemon][replay][mcap][real][threads]") {
  const auto capture = test::real_capture("pandar40p_nebula_dual_600rpm_1262B.pcap");
  if (!capture) return;
  const auto calibration = test::real_capture("nebula_Pandar40P_calibration.csv");
  if (!calibration) return;
  test::ScratchDir dir("replay-recordings-real");
  check_round_trip(*capture, dir.path(), "--calibration " + quoted(*calibration));
}

TEST_CASE("a .pcap.zst of concatenated frames reads as one capture", "[capture][zstd]") {
  test::ScratchDir dir("zstd-frames");
  const fs::path pcap = simulated_capture(dir / "capture.pcap");
  const std::string bytes = harness::read_file(pcap);
  // Cut in the middle of a record: the frames join in the decompressed stream, not per record.
  const std::size_t half = bytes.size() / 2 + 7;
  write_bytes(dir / "a", bytes.substr(0, half));
  write_bytes(dir / "b", bytes.substr(half));
  const std::string joined = harness::read_file(zstd_command(dir / "a", dir / "a.zst")) +
                             harness::read_file(zstd_command(dir / "b", dir / "b.zst"));
  write_bytes(dir / "joined.pcap.zst", joined);
  const Read r = read_recording(dir / "joined.pcap.zst");
  CHECK(r.status == CaptureStatus::kEnd);
  CHECK(r.records.size() == kPackets);
}

TEST_CASE("a cut .pcap.zst (a killed run's .part) gives every complete record, then kTruncated",
          "[capture][zstd][daemon][threads]") {
  test::ScratchDir dir("zstd-cut");
  const fs::path pcap = simulated_capture(dir / "capture.pcap");
  const std::string bytes = harness::read_file(pcap);
  const Read whole = read_recording(pcap);
  REQUIRE(whole.records.size() == kPackets);

  SECTION("flushed at a record boundary, the frame never ended") {
    write_bytes(dir / "run.pcap.zst.part", unfinished_zstd(bytes, 1000));
    const Read r = read_recording(dir / "run.pcap.zst.part");
    CHECK(r.status == CaptureStatus::kTruncated);
    CHECK(r.error.find("run.pcap.zst.part") != std::string::npos);
    CHECK(r.error.find("ends inside a frame") != std::string::npos);
    REQUIRE(r.records.size() == 1000);
    for (std::size_t i = 0; i < r.records.size(); ++i) {
      REQUIRE(r.records[i].payload == whole.records[i].payload);
      REQUIRE(r.records[i].time_ns == whole.records[i].time_ns);
    }
    // The daemon replays what is there and says the file was cut: not whole, exit 65.
    const auto run = test::run_command(test::pandarcapd_command() + " --replay " +
                                       quoted(dir / "run.pcap.zst.part") + " --output-dir " +
                                       quoted(dir / "out") + " 2>&1");
    INFO(run.out);
    CHECK(run.exit_code == 65);
    CHECK(run.out.find("1000 UDP datagrams") != std::string::npos);
    CHECK(run.out.find("cut off while recording") != std::string::npos);
    CHECK(test::last_health_record(dir / "out").at("state") == "degraded");
  }
  SECTION("bytes cut off the end of a zstd -1 file") {
    const std::string zst = harness::read_file(zstd_command(pcap, dir / "capture.pcap.zst"));
    for (const std::size_t keep : {zst.size() - 1, zst.size() / 2, zst.size() / 5}) {
      INFO("kept " << keep << " of " << zst.size());
      write_bytes(dir / "cut.pcap.zst", zst.substr(0, keep));
      const Read r = read_recording(dir / "cut.pcap.zst");
      CHECK(r.status == CaptureStatus::kTruncated);
      CHECK(r.error.find("cut.pcap.zst") != std::string::npos);
      // One byte off: only the frame's checksum is cut, every record is there, and still the
      // frame is unfinished.
      if (keep == zst.size() - 1) {
        CHECK(r.records.size() == whole.records.size());
      } else {
        CHECK(r.records.size() < whole.records.size());
      }
      for (std::size_t i = 0; i < r.records.size(); ++i)
        REQUIRE(r.records[i].payload == whole.records[i].payload);
    }
  }
}

TEST_CASE("corrupt zstd data is an error naming the file", "[capture][zstd][daemon]") {
  test::ScratchDir dir("zstd-corrupt");
  const fs::path pcap = simulated_capture(dir / "capture.pcap");

  SECTION("garbage after the zstd magic: the file cannot be opened") {
    write_bytes(dir / "garbage.pcap.zst",
                std::string("\x28\xb5\x2f\xfd", 4) + std::string(200, '\xa5'));
    try {
      CaptureReader reader((dir / "garbage.pcap.zst").string());
      FAIL("opened");
    } catch (const CaptureError& e) {
      const std::string what = e.what();
      CHECK(what.find("garbage.pcap.zst") != std::string::npos);
      CHECK(what.find("corrupt zstd data") != std::string::npos);
    }
    const auto run = test::run_command(test::pandarcapd_command() + " --replay " +
                                       quoted(dir / "garbage.pcap.zst") + " --output-dir " +
                                       quoted(dir / "out") + " 2>&1");
    INFO(run.out);
    CHECK(run.exit_code == 66);
    CHECK(run.out.find("corrupt zstd data") != std::string::npos);
    const auto inspect = test::run_command(test::binary("pandarcap-inspect").string() + " " +
                                           quoted(dir / "garbage.pcap.zst") + " 2>&1");
    CHECK(inspect.exit_code == 2);
    CHECK(inspect.out.find("corrupt zstd data") != std::string::npos);
  }
  SECTION("a damaged frame after good ones: every record before it, then kError") {
    const std::string zst = harness::read_file(zstd_command(pcap, dir / "capture.pcap.zst"));
    write_bytes(dir / "damaged.pcap.zst",
                zst + std::string("\x28\xb5\x2f\xfd", 4) + std::string(64, '\xff'));
    const Read r = read_recording(dir / "damaged.pcap.zst");
    CHECK(r.status == CaptureStatus::kError);
    CHECK(r.records.size() == kPackets);
    CHECK(r.error.find("damaged.pcap.zst") != std::string::npos);
    CHECK(r.error.find("corrupt zstd data") != std::string::npos);
  }
}

TEST_CASE("an MCAP file without packets, cut or damaged says so", "[daemon][mcap][threads]") {
  test::ScratchDir dir("mcap-replay-errors");
  const fs::path pcap = simulated_capture(dir / "capture.pcap");

  SECTION("no PandarPacket messages: a clear error, exit 66 (inspect 2)") {
    const fs::path mcap = to_mcap(pcap, dir / "points-only", "", false);
    const auto run = test::run_command(test::pandarcapd_command() + " --replay " + quoted(mcap) +
                                       " --output-dir " + quoted(dir / "out") + " 2>&1");
    INFO(run.out);
    CHECK(run.exit_code == 66);
    CHECK(run.out.find("holds no pandar_msgs/msg/PandarPacket messages: record with "
                       "output.mcap_packets = true") != std::string::npos);
    const auto inspect = test::run_command(test::binary("pandarcap-inspect").string() + " " +
                                           quoted(mcap) + " 2>&1");
    CHECK(inspect.exit_code == 2);
    CHECK(inspect.out.find("holds no pandar_msgs/msg/PandarPacket") != std::string::npos);
  }

  const fs::path mcap = to_mcap(pcap, dir / "convert");
  const std::string bytes = harness::read_file(mcap);
  const Read whole = read_recording(mcap);
  REQUIRE(whole.records.size() == kPackets);

  SECTION("cut: every packet before the cut, then kTruncated") {
    write_bytes(dir / "cut.mcap", bytes.substr(0, bytes.size() / 2));
    const Read r = read_recording(dir / "cut.mcap");
    CHECK(r.status == CaptureStatus::kTruncated);
    CHECK(r.error.find("cut.mcap") != std::string::npos);
    CHECK(r.records.size() > 0);
    CHECK(r.records.size() < kPackets);
    for (std::size_t i = 0; i < r.records.size(); ++i)
      REQUIRE(r.records[i].payload == whole.records[i].payload);
  }
  SECTION("a chunk claiming an absurd size: a clear error before any allocation, skipped") {
    std::string damaged = bytes;
    std::size_t chunks = 0;
    for (const auto& [at, op] : mcap_records(bytes)) {
      if (op != static_cast<std::uint8_t>(mcap::Op::kChunk)) continue;
      if (++chunks < 2) continue;  // the second chunk: the first gives packets before it
      const std::uint64_t absurd = std::uint64_t{1} << 40;
      std::memcpy(damaged.data() + at + 9 + 16, &absurd, 8);  // start, end, uncompressed size
      break;
    }
    REQUIRE(chunks == 2);
    write_bytes(dir / "absurd.mcap", damaged);
    // Skipped by the chunk index: the packets before and after it are read.
    CaptureReader reader((dir / "absurd.mcap").string());
    CaptureRecord record;
    std::size_t records = 0;
    CaptureStatus status;
    while ((status = reader.next(record)) == CaptureStatus::kRecord)
      ++records;
    CHECK(status == CaptureStatus::kEnd);
    CHECK(reader.stats().chunks_skipped == 1);
    CHECK(records + reader.stats().packets_skipped == kPackets);
    CHECK(reader.first_damage().find("absurd.mcap") != std::string::npos);
    CHECK(reader.first_damage().find("claims 1099511627776 bytes uncompressed") !=
          std::string::npos);
  }
  SECTION("--port and --sensor-ip cannot apply: replayed whole, with a warning") {
    const auto run = test::run_command(test::pandarcapd_command() + " --replay " + quoted(mcap) +
                                       " --port 2368 --sensor-ip 10.0.0.9 --output-dir " +
                                       quoted(dir / "out") + " 2>&1");
    INFO(run.out);
    CHECK(run.exit_code == 0);
    CHECK(run.out.find("carry no addresses") != std::string::npos);
    CHECK(run.out.find(std::to_string(kPackets) + " UDP datagrams") != std::string::npos);
  }
}
