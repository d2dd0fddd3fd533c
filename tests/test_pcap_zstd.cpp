// Compressed recordings (output.pcap_compression = "zstd", raw/NAME.pcap.zst): the same pcap
// stream as an uncompressed recording, one zstd frame per file that tshark reads as it is; a flush
// makes everything written so far decompressible from the file; a full disk leaves a complete
// frame of the flushed records; a killed run's .pcap.zst.part is finished at the next start with
// every whole record it held.
#include <signal.h>
#include <zstd.h>

#include <array>
#include <catch2/catch.hpp>
#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <regex>
#include <string>
#include <vector>

#include "bench/child_process.hpp"
#include "core/sim/synthetic_sensor.hpp"
#include "daemon/io/syscalls.hpp"
#include "daemon/pcap/capture_reader.hpp"
#include "daemon/pcap/pcap_recovery.hpp"
#include "daemon/pcap/pcap_writer.hpp"
#include "daemon/pcap/xxh64.hpp"
#include "daemon/pcap/zstd_write_stream.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
using namespace std::chrono_literals;
namespace fs = std::filesystem;

namespace {

constexpr Endpoint kZstdSource{0x7F000001, 10000};
constexpr Endpoint kZstdDestination{0x7F000001, 2368};
constexpr std::int64_t kZstdTime = 1'795'348'800'000'000'000;

// A Pandar-sized payload that compresses as real ones do (not all one byte).
std::vector<std::uint8_t> zstd_payload(int i) {
  std::vector<std::uint8_t> bytes(1262);
  for (std::size_t k = 0; k < bytes.size(); ++k)
    bytes[k] = static_cast<std::uint8_t>((k * 7 + static_cast<std::size_t>(i) * 13) % 251 ^
                                         (k % 3 == 0 ? i : 0));
  return bytes;
}

// The file's bytes decompressed by libzstd directly (an independent reading of the frame), and
// whether the frame was complete (ended, nothing after it).
struct Decompressed {
  std::string bytes;
  bool complete = false;
  bool error = false;
};
Decompressed decompress(const std::string& compressed) {
  Decompressed out;
  ZSTD_DCtx* context = ZSTD_createDCtx();
  ZSTD_inBuffer in{compressed.data(), compressed.size(), 0};
  std::vector<char> chunk(1 << 16);
  std::size_t last = 1;
  while (in.pos < in.size) {
    ZSTD_outBuffer o{chunk.data(), chunk.size(), 0};
    last = ZSTD_decompressStream(context, &o, &in);
    if (ZSTD_isError(last)) {
      out.error = true;
      break;
    }
    out.bytes.append(chunk.data(), o.pos);
    if (o.pos == 0 && in.pos == in.size) break;
  }
  // Drain what is still held once the input is used up (a frame that ended says 0: nothing
  // more to come; asked again, it would hint at the next frame's header).
  while (!out.error && last != 0) {
    ZSTD_outBuffer o{chunk.data(), chunk.size(), 0};
    ZSTD_inBuffer none{nullptr, 0, 0};
    last = ZSTD_decompressStream(context, &o, &none);
    if (ZSTD_isError(last)) {
      out.error = true;
      break;
    }
    out.bytes.append(chunk.data(), o.pos);
    if (o.pos < chunk.size()) break;
  }
  ZSTD_freeDCtx(context);
  out.complete = !out.error && last == 0;
  return out;
}

// tshark (Wireshark 4.0) reads the file: how many packets, or -1 when it reports an error. Under
// CI=true a missing tshark fails the test; elsewhere it is skipped with a warning (0 returned as
// "not checked" is never confused with a count: callers REQUIRE a count when it is installed).
bool have_tshark() {
  if (test::run_command("command -v tshark >/dev/null").exit_code == 0) return true;
  if (std::getenv("CI") != nullptr && std::string(std::getenv("CI")) == "true") {
    FAIL("tshark is not installed (.ci/install-deps installs it)");
  }
  WARN("tshark is not installed: the Wireshark half not tested");
  return false;
}
long tshark_packets(const fs::path& file) {
  const auto result =
      test::run_command("tshark -r '" + file.string() + "' -T fields -e frame.number 2>&1");
  if (result.exit_code != 0) return -1;
  long lines = 0;
  for (char c : result.out)
    lines += c == '\n';
  // tshark warns when run as root, on its own line: not a packet.
  if (result.out.find("Running as user") != std::string::npos) --lines;
  return lines;
}

// Writes `records` packets through `writer`, flushing every `flush_every`.
void write_packets(PcapWriter& writer, int records, int flush_every) {
  for (int i = 0; i < records; ++i) {
    writer.write(zstd_payload(i), kZstdTime + i * 1000, kZstdSource, kZstdDestination);
    if ((i + 1) % flush_every == 0) writer.flush();
  }
}

}  // namespace

TEST_CASE("a compressed recording is the uncompressed one byte for byte, readable at each flush",
          "[pcap][zstd]") {
  test::ScratchDir dir("pcap-zstd");
  std::vector<char> plain_buffer(kPcapBufferBytes), zst_buffer(kPcapBufferBytes);
  ZstdStreamCompressor compressor(kPcapBufferBytes, 1);
  PcapWriter plain((dir / "r.pcap").string(), plain_buffer);
  PcapWriter zst((dir / "r.pcap.zst").string(), zst_buffer, &compressor);
  CHECK(zst.compressed());
  // Large enough that the 1 MiB buffer fills between flushes (kContinue output in between).
  for (int round = 0; round < 3; ++round) {
    for (int i = 0; i < 1000; ++i) {
      plain.write(zstd_payload(i), kZstdTime + i * 1000, kZstdSource, kZstdDestination);
      zst.write(zstd_payload(i), kZstdTime + i * 1000, kZstdSource, kZstdDestination);
    }
    plain.flush();
    zst.flush();
    // Not yet ended, but everything given so far comes out of the file as it stands.
    const Decompressed so_far = decompress(harness::read_file(dir / "r.pcap.zst"));
    CHECK_FALSE(so_far.error);
    CHECK_FALSE(so_far.complete);
    CHECK(so_far.bytes == harness::read_file(dir / "r.pcap"));
    CHECK(zst.flushed_bytes() == fs::file_size(dir / "r.pcap.zst"));
  }
  plain.close();
  zst.close();
  const Decompressed whole = decompress(harness::read_file(dir / "r.pcap.zst"));
  CHECK(whole.complete);
  CHECK(whole.bytes == harness::read_file(dir / "r.pcap"));
  CHECK(zst.bytes() == fs::file_size(dir / "r.pcap.zst"));
  CHECK(zst.records() == 3000);
  // Smaller: these payloads repeat with a short period, so by far.
  CHECK(fs::file_size(dir / "r.pcap.zst") * 3 < fs::file_size(dir / "r.pcap"));
  if (have_tshark()) CHECK(tshark_packets(dir / "r.pcap.zst") == 3000);

  // One compressor serves the next file: a new frame, nothing carried over.
  PcapWriter next((dir / "s.pcap.zst").string(), zst_buffer, &compressor);
  write_packets(next, 10, 5);
  next.close();
  const Decompressed second = decompress(harness::read_file(dir / "s.pcap.zst"));
  CHECK(second.complete);
  CHECK(second.bytes.size() == kPcapGlobalHeaderBytes + 10 * (kPcapRecordOverheadBytes + 1262));
}

TEST_CASE("a compressed recording the disk filled is a complete frame of its flushed records",
          "[pcap][zstd][io]") {
  test::ScratchDir dir("pcap-zstd-full");
  const fs::path path = dir / "full.pcap.zst.part";
  std::vector<char> buffer(kPcapBufferBytes);
  ZstdStreamCompressor compressor(kPcapBufferBytes, 1);
  static std::size_t space = SIZE_MAX;
  io::FileSyscalls calls = io::real_file_syscalls();
  calls.write = [](int fd, const void* data, std::size_t size) -> ssize_t {
    if (space == 0) {
      errno = ENOSPC;
      return -1;
    }
    const ssize_t n = ::write(fd, data, std::min(size, space));
    if (n > 0) space -= static_cast<std::size_t>(n);
    return n;
  };
  const io::ScopedFileSyscalls seam(calls);
  PcapWriter writer(path.string(), buffer, &compressor);
  write_packets(writer, 40, 20);
  REQUIRE(writer.flushed_records() == 40);
  for (int i = 0; i < 500; ++i)
    writer.write(zstd_payload(i), kZstdTime, kZstdSource, kZstdDestination);
  space = 100;  // the disk takes part of the next flush, then no more
  CHECK_THROWS_AS(writer.flush(), std::system_error);
  space = 100;  // cutting the file back gives back what the failed flush took
  const PcapWriter::Dropped dropped = writer.abandon();
  CHECK(dropped.records == 500);
  CHECK(dropped.bytes == 500 * (kPcapRecordOverheadBytes + 1262));
  // The 100 bytes of the failed flush were taken back; 3 bytes ended the frame, and 4 more are
  // its content checksum, of the flushed records: zstd checks it.
  space = SIZE_MAX;
  CHECK(fs::file_size(path) == writer.flushed_bytes() + kZstdEmptyLastBlock.size() + 4);
  const Decompressed back = decompress(harness::read_file(path));
  CHECK(back.complete);
  CHECK(back.bytes.size() == kPcapGlobalHeaderBytes + 40 * (kPcapRecordOverheadBytes + 1262));
  const fs::path finished = dir / "full.pcap.zst";
  fs::rename(path, finished);
  if (have_tshark()) CHECK(tshark_packets(finished) == 40);
}

TEST_CASE("finish_interrupted_pcap_zst on a disk with no room for a copy: ended in place",
          "[pcap][zstd][recovery]") {
  // The copy is refused (ENOSPC through the seam, as a disk our own recordings filled): the
  // frame is cut after its last block that ends on a whole record, which every flush makes, and
  // ended there, checksum and all, without a byte more on the disk.
  test::ScratchDir dir("pcap-zstd-recovery-in-place");
  std::vector<char> buffer(kPcapBufferBytes);
  ZstdStreamCompressor compressor(kPcapBufferBytes, 1);
  const fs::path whole = dir / "whole.pcap.zst";
  std::vector<std::uint64_t> flushed_at;  // the file's size after each flush
  {
    PcapWriter writer(whole.string(), buffer, &compressor);
    SyntheticSensor sensor(SyntheticSensorConfig{});
    std::array<std::uint8_t, kMaxPacketBytes> packet{};
    for (int i = 0; i < 2000; ++i) {
      const std::size_t size = sensor.next(packet);
      writer.write({packet.data(), size}, kZstdTime + i * 1000, kZstdSource, kZstdDestination);
      if ((i + 1) % 250 == 0) {
        writer.flush();
        flushed_at.push_back(writer.bytes());
      }
    }
    writer.close();
  }
  const std::string bytes = harness::read_file(whole);
  const std::string stream = decompress(bytes).bytes;
  const std::size_t record = kPcapRecordOverheadBytes + 1262;
  io::FileSyscalls calls = io::real_file_syscalls();
  calls.write = [](int, const void*, std::size_t) -> ssize_t {
    errno = ENOSPC;
    return -1;
  };
  int checked = 0;
  for (std::size_t cut = 0; cut < bytes.size(); cut += 1 + bytes.size() / 53) {
    INFO("cut at " << cut << " of " << bytes.size());
    const fs::path part = dir / "cut.pcap.zst.part";
    std::ofstream(part, std::ios::binary) << bytes.substr(0, cut);
    std::size_t flushes = 0;  // the flushes the cut file holds whole
    while (flushes < flushed_at.size() && flushed_at[flushes] <= cut)
      ++flushes;
    PcapRecovery r;
    {
      const io::ScopedFileSyscalls seam(calls);
      r = finish_interrupted_pcap_zst(part.string());
    }
    CHECK(r.ours);
    CHECK(r.records >= 250 * flushes);
    CHECK(fs::file_size(part) <= cut + 7);  // an empty last block and the checksum at most
    if (r.records > 0) {
      const Decompressed finished = decompress(harness::read_file(part));
      CHECK(finished.complete);  // ended, and its content checksum right
      CHECK(finished.bytes == stream.substr(0, kPcapGlobalHeaderBytes + r.records * record));
      CHECK(r.kept_bytes == fs::file_size(part));
    }
    CHECK(test::files_ending(dir.path(), ".tmp").empty());
    ++checked;
  }
  CHECK(checked >= 30);
}

TEST_CASE("finish_interrupted_pcap_zst keeps every whole record of a frame cut anywhere",
          "[pcap][zstd][recovery]") {
  test::ScratchDir dir("pcap-zstd-recovery");
  std::vector<char> buffer(8192);  // small: blocks end mid-record between flushes
  ZstdStreamCompressor compressor(kPcapBufferBytes, 1);
  const fs::path whole = dir / "whole.pcap.zst";
  {
    // Megabytes of the simulated sensor's packets (they compress as real ones do): the reader's
    // output fills now and then just as its input runs out, and what the decompressor holds
    // back then must still come out at the end of the file.
    PcapWriter writer(whole.string(), buffer, &compressor);
    SyntheticSensor sensor(SyntheticSensorConfig{});
    std::array<std::uint8_t, kMaxPacketBytes> packet{};
    for (int i = 0; i < 2000; ++i) {
      const std::size_t size = sensor.next(packet);
      REQUIRE(size == 1262);
      writer.write({packet.data(), size}, kZstdTime + i * 1000, kZstdSource, kZstdDestination);
      if ((i + 1) % 250 == 0) writer.flush();
    }
    writer.close();
  }
  const std::string bytes = harness::read_file(whole);
  const std::string stream = decompress(bytes).bytes;
  const std::size_t record = kPcapRecordOverheadBytes + 1262;
  REQUIRE(stream.size() == kPcapGlobalHeaderBytes + 2000 * record);
  int checked = 0;
  for (std::size_t cut = 0; cut <= bytes.size(); cut += 1 + bytes.size() / 97) {
    INFO("cut at " << cut << " of " << bytes.size());
    const fs::path part = dir / "cut.pcap.zst.part";
    std::ofstream(part, std::ios::binary) << bytes.substr(0, cut);
    // What the cut file decompresses to, independently: its whole records must all be kept.
    const Decompressed prefix = decompress(bytes.substr(0, cut));
    const std::size_t whole_records = prefix.bytes.size() < kPcapGlobalHeaderBytes
                                          ? 0
                                          : (prefix.bytes.size() - kPcapGlobalHeaderBytes) / record;
    const PcapRecovery r = finish_interrupted_pcap_zst(part.string());
    CHECK(r.ours);
    CHECK(r.records == whole_records);
    if (whole_records > 0) {
      const Decompressed finished = decompress(harness::read_file(part));
      CHECK(finished.complete);
      CHECK(finished.bytes == stream.substr(0, kPcapGlobalHeaderBytes + whole_records * record));
      CHECK(r.kept_bytes == fs::file_size(part));
      CHECK(r.cut_bytes == prefix.bytes.size() - kPcapGlobalHeaderBytes - whole_records * record);
    }
    CHECK(test::files_ending(dir.path(), ".tmp").empty());
    ++checked;
  }
  CHECK(checked >= 30);
  // A file cut on a flush holds a finished frame tshark reads to its end.
  const fs::path part = dir / "tshark.pcap.zst.part";
  std::ofstream(part, std::ios::binary) << bytes.substr(0, bytes.size() * 2 / 3);
  const PcapRecovery r = finish_interrupted_pcap_zst(part.string());
  REQUIRE(r.records > 0);
  const fs::path done = dir / "tshark.pcap.zst";
  fs::rename(part, done);
  if (have_tshark()) CHECK(tshark_packets(done) == static_cast<long>(r.records));
}

TEST_CASE("finish_interrupted_pcap_zst: empty, a magic cut short, and files not ours",
          "[pcap][zstd][recovery]") {
  test::ScratchDir dir("pcap-zstd-foreign");
  const auto recover = [&](const std::string& name, const std::string& bytes) {
    const fs::path part = dir / name;
    std::ofstream(part, std::ios::binary) << bytes;
    return finish_interrupted_pcap_zst(part.string());
  };
  PcapRecovery r = recover("empty.pcap.zst.part", "");
  CHECK(r.ours);
  CHECK(r.records == 0);
  r = recover("magic.pcap.zst.part", std::string("\x28\xB5", 2));
  CHECK(r.ours);
  CHECK(r.records == 0);
  // Not zstd at all, and zstd of something else: left exactly as they were.
  const std::string text = "not a recording of ours\n";
  r = recover("text.pcap.zst.part", text);
  CHECK_FALSE(r.ours);
  CHECK(harness::read_file(dir / "text.pcap.zst.part") == text);
  ZstdStreamCompressor compressor(1024, 1);
  const auto frame = compressor.compress(
      std::span(reinterpret_cast<const std::uint8_t*>(text.data()), text.size()),
      ZstdStreamCompressor::Step::kEnd);
  const std::string other(reinterpret_cast<const char*>(frame.data()), frame.size());
  r = recover("other.pcap.zst.part", other);
  CHECK_FALSE(r.ours);
  CHECK(harness::read_file(dir / "other.pcap.zst.part") == other);
  // Never through a link.
  fs::create_symlink(dir / "other.pcap.zst.part", dir / "link.pcap.zst.part");
  CHECK_THROWS_AS(finish_interrupted_pcap_zst((dir / "link.pcap.zst.part").string()),
                  std::system_error);
  CHECK(test::files_ending(dir.path(), ".tmp").empty());
}

TEST_CASE(
    "pandarcapd --pcap-compression zstd: a killed run's recording is finished at the next "
    "start and tshark reads every packet of it",
    "[daemon][zstd][recovery][threads]") {
  test::ScratchDir dir("daemon-zstd-kill");
  const fs::path out = dir / "out";
  harness::ChildProcess first(
      test::binary("pandarcapd"),
      {"--allow-root", "--simulate", "--pcap-compression", "zstd", "--output-dir", out.string()},
      dir / "first.txt");
  REQUIRE(harness::wait_until([&] { return first.logged("ready:"); }, 20s));
  // Killed once a second of packets is on disk (each batch is flushed whole).
  REQUIRE(harness::wait_until(
      [&] {
        const auto parts = test::files_ending(out / "raw", ".pcap.zst.part");
        return !parts.empty() && fs::file_size(parts.front()) > 1'000'000;
      },
      20s));
  first.signal(SIGKILL);
  REQUIRE(first.wait_exit(10s) == -SIGKILL);
  const auto parts = test::files_ending(out / "raw", ".pcap.zst.part");
  REQUIRE(parts.size() == 1);
  const Decompressed left = decompress(harness::read_file(parts.front()));
  CHECK_FALSE(left.error);
  CHECK_FALSE(left.complete);  // the frame was never ended
  const std::size_t at_least = (left.bytes.size() - kPcapGlobalHeaderBytes) / (1262 + 58);

  harness::ChildProcess second(test::binary("pandarcapd"),
                               {"--allow-root", "--simulate", "--duration", "1",
                                "--pcap-compression", "zstd", "--output-dir", out.string()},
                               dir / "second.txt");
  REQUIRE(second.wait_exit(30s) == 0);
  INFO(second.log());
  const std::string part = parts.front().string();
  const fs::path finished = part.substr(0, part.size() - 5);
  REQUIRE(fs::exists(finished));
  CHECK(test::files_ending(out / "raw", ".part").empty());
  std::smatch m;
  const std::string log = second.log();
  REQUIRE(std::regex_search(log, m, std::regex(R"(\((\d+) whole records, )")));
  const std::size_t kept = std::stoul(m[1]);
  CHECK(kept == at_least);  // every record the file held whole
  CHECK(decompress(harness::read_file(finished)).complete);
  // Both recordings are numbered on (the earlier one adopted) and read by tshark.
  const auto recordings = test::files_ending(out / "raw", ".pcap.zst");
  REQUIRE(recordings.size() == 2);
  CHECK(recordings[0] == finished);
  CHECK(recordings[1].filename().string().find("_0001.pcap.zst") != std::string::npos);
  if (have_tshark()) {
    CHECK(tshark_packets(finished) == static_cast<long>(kept));
    CHECK(tshark_packets(recordings[1]) > 0);
  }
}

TEST_CASE(
    "a full disk while compressing: every recording left is a complete frame, and the "
    "packets recorded are the packets on disk",
    "[daemon][zstd][disk][threads]") {
  test::ScratchDir dir("daemon-zstd-full");
  const fs::path mount_point = dir / "out";
  fs::create_directories(mount_point);
  const fs::path config = dir / "full.toml";
  // Small recordings: several are finished before the disk fills, one is open when it does.
  std::ofstream(config) << "[output]\npcap_rotate_bytes = 262144\npcap_compression = \"zstd\"\n";
  const auto args = test::tmpfs_run_args(
      mount_point, "48m", test::binary("pandarcapd"),
      {"--allow-root", "-c", config.string(), "--simulate", "--output-dir", mount_point.string()},
      true);
  if (args.empty()) {
    WARN("cannot create a mount namespace here (no root, no user namespaces): not tested");
    return;
  }
  harness::ChildProcess daemon("/usr/bin/unshare", args, dir / "log.txt");
  INFO(daemon.log());
  REQUIRE(harness::wait_until([&] { return daemon.logged("ready:"); }, 20s));
  const int pid = test::tmpfs_program_pid(mount_point);
  REQUIRE(pid > 0);
  const fs::path view = test::tmpfs_view(pid, mount_point);
  // Frames and recordings fill the 48 MB down to what the health files keep.
  REQUIRE(harness::wait_until(
      [&] {
        return test::health_counter(test::last_health_record(view), "pcap_packets_not_written") > 0;
      },
      30s));
  REQUIRE(::kill(pid, SIGTERM) == 0);
  REQUIRE(daemon.wait_exit(20s) == 0);
  std::smatch m;
  const std::string log = daemon.log();
  INFO(log);
  REQUIRE(
      std::regex_search(log, m, std::regex(R"((\d+) packets recorded[^;]*; (\d+) write errors)")));
  CHECK(std::stoul(m[2]) > 0);
  const auto recordings =
      test::files_ending(fs::path(mount_point.string() + ".after") / "raw", ".pcap.zst");
  REQUIRE(recordings.size() >= 2);
  CHECK(test::files_ending(fs::path(mount_point.string() + ".after") / "raw", ".part").empty());
  std::uint64_t on_disk = 0;
  for (const fs::path& file : recordings) {
    INFO(file.string());
    const Decompressed d = decompress(harness::read_file(file));
    CHECK(d.complete);
    const std::uint64_t packets = (d.bytes.size() - kPcapGlobalHeaderBytes) / (1262 + 58);
    CHECK(d.bytes.size() == kPcapGlobalHeaderBytes + packets * (1262 + 58));
    on_disk += packets;
  }
  CHECK(on_disk == std::stoul(m[1]));
  if (have_tshark()) {
    std::uint64_t read = 0;
    for (const fs::path& file : recordings)
      read += static_cast<std::uint64_t>(std::max(0L, tshark_packets(file)));
    CHECK(read == on_disk);
  }
}

TEST_CASE("the real capture recorded compressed: the same pcap stream in under 0.30 of its bytes",
          "[daemon][zstd][real][threads]") {
  const auto capture = test::real_capture("pandar40p_nebula_dual_600rpm_1262B.pcap");
  if (!capture) return;
  test::ScratchDir dir("zstd-real");
  const auto record = [&](const std::string& name, const std::string& compression) {
    const auto result =
        test::run_command(test::pandarcapd_command() + " --replay '" + capture->string() +
                          "' --max-clock-offset 0 --pcap-compression " + compression +
                          " --output-dir '" + (dir / name).string() + "' 2>&1");
    INFO(result.out);
    REQUIRE(result.exit_code == 0);
    CHECK(result.out.find("1439 packets recorded; 0 write errors") != std::string::npos);
  };
  record("plain", "none");
  record("zstd", "zstd");
  const auto plain = test::files_ending(dir / "plain" / "raw", ".pcap");
  const auto zst = test::files_ending(dir / "zstd" / "raw", ".pcap.zst");
  REQUIRE(plain.size() == 1);
  REQUIRE(zst.size() == 1);
  const Decompressed d = decompress(harness::read_file(zst.front()));
  CHECK(d.complete);
  CHECK(d.bytes == harness::read_file(plain.front()));  // byte for byte the uncompressed recording
  const double ratio = static_cast<double>(fs::file_size(zst.front())) /
                       static_cast<double>(fs::file_size(plain.front()));
  INFO("compressed to " << ratio << " of the pcap's bytes");
  CHECK(ratio <= 0.30);
  if (have_tshark()) CHECK(tshark_packets(zst.front()) == 1439);
}

TEST_CASE("Xxh64 gives zstd's own content checksum, fed in any pieces", "[pcap][zstd]") {
  std::vector<std::uint8_t> content(100'003);
  for (std::size_t i = 0; i < content.size(); ++i)
    content[i] = static_cast<std::uint8_t>((i * 2654435761u) >> 13);
  ZSTD_CCtx* cctx = ZSTD_createCCtx();
  ZSTD_CCtx_setParameter(cctx, ZSTD_c_checksumFlag, 1);
  for (const std::size_t size : {0, 1, 3, 4, 5, 8, 31, 32, 33, 63, 64, 1000, 100'003}) {
    for (const std::size_t piece :
         {std::size_t{1}, std::size_t{7}, std::size_t{32}, std::size_t{1000}, size + 1}) {
      INFO(size << " bytes in pieces of " << piece);
      Xxh64 hash;
      for (std::size_t at = 0; at < size; at += piece)
        hash.update({content.data() + at, std::min(piece, size - at)});
      std::vector<std::uint8_t> frame(ZSTD_compressBound(size) + 64);
      const std::size_t n = ZSTD_compress2(cctx, frame.data(), frame.size(), content.data(), size);
      REQUIRE_FALSE(ZSTD_isError(n));
      const auto expected =
          std::array<std::uint8_t, 4>{frame[n - 4], frame[n - 3], frame[n - 2], frame[n - 1]};
      CHECK(zstd_content_checksum(hash) == expected);
    }
  }
  ZSTD_freeCCtx(cctx);
}
