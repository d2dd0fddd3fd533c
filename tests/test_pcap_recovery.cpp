// Recordings left unfinished: PcapWriter::abandon() after a failed write, and
// finish_interrupted_pcap() for a ".part" a killed run left. Either way the file must end on a
// whole record, so readers (libpcap, tcpdump) read it to the end, and nothing else is touched.
#include <unistd.h>

#include <algorithm>
#include <catch2/catch.hpp>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "daemon/output/output_accounting.hpp"
#include "daemon/output/output_leftovers.hpp"
#include "daemon/pcap/capture_reader.hpp"
#include "daemon/pcap/pcap_recovery.hpp"
#include "daemon/pcap/pcap_writer.hpp"
#include "support/page_cache.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
namespace fs = std::filesystem;

namespace {

constexpr Endpoint kSource{0x7F000001, 10000};
constexpr Endpoint kDestination{0x7F000001, 2368};
constexpr std::int64_t kTime = 1'795'348'800'000'000'000;

std::vector<std::uint8_t> payload(std::size_t n, std::uint8_t fill) {
  return std::vector<std::uint8_t>(n, fill);
}

// Reads `path` to its end: the records and how the read ended.
struct ReadBack {
  std::vector<std::size_t> sizes;
  CaptureStatus status = CaptureStatus::kError;
};
ReadBack read_back(const fs::path& path) {
  CaptureReader reader(path.string());
  CaptureRecord record;
  ReadBack result;
  while ((result.status = reader.next(record)) == CaptureStatus::kRecord)
    result.sizes.push_back(record.payload.size());
  return result;
}

// A recording of `records` datagrams of 1262 bytes, closed properly; returns its size.
std::uint64_t write_recording(const fs::path& path, int records) {
  PcapWriter writer(path.string());
  for (int i = 0; i < records; ++i)
    writer.write(payload(1262, static_cast<std::uint8_t>(i)), kTime + i * 1000, kSource,
                 kDestination);
  writer.close();
  return writer.bytes();
}

}  // namespace

TEST_CASE("finish_interrupted_pcap cuts a record cut anywhere and keeps every whole one",
          "[pcap][recovery]") {
  test::ScratchDir dir("pcap-recovery");
  const fs::path whole = dir / "whole.pcap";
  const std::uint64_t three = write_recording(whole, 3);
  const std::uint64_t record_bytes = 16 + 42 + 1262;
  REQUIRE(three == 24 + 3 * record_bytes);
  // A fourth record written in part: inside its header, at its end of header, inside its data,
  // one byte short of whole.
  const fs::path four = dir / "four.pcap";
  const std::uint64_t full = write_recording(four, 4);
  for (const std::uint64_t cut_at : {three + 1, three + 15, three + 16, three + 700, full - 1}) {
    const fs::path part = dir / ("cut-" + std::to_string(cut_at) + ".pcap.part");
    fs::copy_file(four, part);
    fs::resize_file(part, cut_at);
    INFO("cut at " << cut_at);
    CHECK(read_back(part).status == CaptureStatus::kTruncated);  // as a crash leaves it
    const PcapRecovery recovered = finish_interrupted_pcap(part.string());
    CHECK(recovered.ours);
    CHECK(recovered.records == 3);
    CHECK(recovered.kept_bytes == three);
    CHECK(recovered.cut_bytes == cut_at - three);
    CHECK(fs::file_size(part) == three);
    const ReadBack after = read_back(part);
    CHECK(after.status == CaptureStatus::kEnd);
    CHECK(after.sizes == std::vector<std::size_t>(3, 1262));
  }
  // A whole file is left as it is.
  const PcapRecovery untouched = finish_interrupted_pcap(whole.string());
  CHECK(untouched.records == 3);
  CHECK(untouched.cut_bytes == 0);
  CHECK(fs::file_size(whole) == three);
}

TEST_CASE("finish_interrupted_pcap: headers only, empty, garbage tails and foreign files",
          "[pcap][recovery]") {
  test::ScratchDir dir("pcap-recovery-edges");
  const fs::path header_only = dir / "header.pcap.part";
  write_recording(header_only, 0);
  PcapRecovery r = finish_interrupted_pcap(header_only.string());
  CHECK(r.ours);
  CHECK(r.records == 0);
  CHECK(r.kept_bytes == 24);

  // Killed before the header was all written: ours, no record (the caller removes it).
  const fs::path empty = dir / "empty.pcap.part";
  std::ofstream(empty).close();
  r = finish_interrupted_pcap(empty.string());
  CHECK(r.ours);
  CHECK(r.records == 0);
  for (const std::uintmax_t cut : {1u, 4u, 23u}) {
    const fs::path part = dir / ("header-cut-" + std::to_string(cut) + ".pcap.part");
    fs::copy_file(header_only, part);
    fs::resize_file(part, cut);
    r = finish_interrupted_pcap(part.string());
    INFO("header cut to " << cut << " bytes");
    CHECK(r.ours);
    CHECK(r.records == 0);
  }
  // A short file that is not the start of our header is not ours.
  const fs::path short_text = dir / "short.pcap.part";
  std::ofstream(short_text) << "hello";
  CHECK_FALSE(finish_interrupted_pcap(short_text.string()).ours);

  // A record header claiming more than the snap length is where the good part ends.
  const fs::path garbage = dir / "garbage.pcap.part";
  const std::uint64_t two = write_recording(garbage, 2);
  {
    std::ofstream out(garbage, std::ios::binary | std::ios::app);
    const std::vector<char> junk(40, '\xff');
    out.write(junk.data(), static_cast<std::streamsize>(junk.size()));
  }
  r = finish_interrupted_pcap(garbage.string());
  CHECK(r.records == 2);
  CHECK(r.cut_bytes == 40);
  CHECK(fs::file_size(garbage) == two);

  // Not a file of ours (here: text): reported, not touched.
  const fs::path foreign = dir / "foreign.pcap.part";
  std::ofstream(foreign) << "this is not a capture file, whatever its name says\n";
  const auto size = fs::file_size(foreign);
  r = finish_interrupted_pcap(foreign.string());
  CHECK_FALSE(r.ours);
  CHECK(fs::file_size(foreign) == size);

  CHECK_THROWS_AS(finish_interrupted_pcap((dir / "missing.pcap.part").string()), std::system_error);
}

TEST_CASE("PcapWriter::abandon keeps what the last good flush wrote and counts the rest",
          "[pcap][recovery]") {
  test::ScratchDir dir("pcap-abandon");
  const fs::path path = dir / "a.pcap.part";
  PcapWriter writer(path.string());
  for (int i = 0; i < 3; ++i)
    writer.write(payload(1262, 1), kTime, kSource, kDestination);
  writer.flush();
  CHECK(writer.flushed_records() == 3);
  const std::uint64_t flushed = writer.flushed_bytes();
  for (int i = 0; i < 2; ++i)
    writer.write(payload(100, 2), kTime, kSource, kDestination);
  CHECK(writer.records() == 5);
  const PcapWriter::Dropped dropped = writer.abandon();
  CHECK(dropped.records == 2);
  CHECK(dropped.bytes == 2 * (16 + 42 + 100));
  CHECK(writer.records() == 3);
  CHECK(fs::file_size(path) == flushed);
  const ReadBack back = read_back(path);
  CHECK(back.status == CaptureStatus::kEnd);
  CHECK(back.sizes == std::vector<std::size_t>(3, 1262));
  // Abandoned is closed: further writes fail loudly, closing again is harmless.
  CHECK_THROWS_AS(writer.write(payload(10, 0), kTime, kSource, kDestination), std::system_error);
  CHECK_NOTHROW(writer.close());

  // No record ever flushed: the global header, written at once on creation, is all that stays
  // (a valid, empty capture; the daemon removes such a file).
  const fs::path never = dir / "never.pcap.part";
  PcapWriter unflushed(never.string());
  CHECK(fs::file_size(never) == 24);
  unflushed.write(payload(1262, 1), kTime, kSource, kDestination);
  const PcapWriter::Dropped all = unflushed.abandon();
  CHECK(all.records == 1);
  CHECK(all.bytes == 16 + 42 + 1262);
  CHECK(unflushed.flushed_records() == 0);
  CHECK(fs::file_size(never) == 24);
  CHECK(read_back(never).status == CaptureStatus::kEnd);
}

TEST_CASE("a recorded datagram that was cut (captured < original) is a whole record to recovery",
          "[pcap][recovery]") {
  test::ScratchDir dir("pcap-recovery-cut-datagram");
  const fs::path part = dir / "cut.pcap.part";
  {
    PcapWriter writer(part.string());
    writer.write(payload(1262, 1), kTime, kSource, kDestination);
    writer.write(payload(1280, 2), 65507, kTime + 1000, kSource, kDestination);
    writer.write(payload(1262, 3), kTime + 2000, kSource, kDestination);
    writer.close();
  }
  const auto size = fs::file_size(part);
  const PcapRecovery recovered = finish_interrupted_pcap(part.string());
  CHECK(recovered.ours);
  CHECK(recovered.records == 3);
  CHECK(recovered.kept_bytes == size);
  CHECK(recovered.cut_bytes == 0);
  CHECK(read_back(part).sizes == std::vector<std::size_t>{1262, 1280, 1262});
}

TEST_CASE("finish_interrupted_pcap never follows a symbolic link", "[pcap][recovery]") {
  test::ScratchDir dir("pcap-recovery-link");
  const fs::path target = dir / "elsewhere.pcap";
  write_recording(target, 2);
  std::ofstream(target, std::ios::binary | std::ios::app) << "cut";
  const auto size = fs::file_size(target);
  const fs::path link = dir / "x.pcap.part";
  fs::create_symlink(target, link);
  CHECK_THROWS_AS(finish_interrupted_pcap(link.string()), std::system_error);
  CHECK(fs::file_size(target) == size);
}

// Once synced, every recording the finisher puts in place leaves the page cache (its partly
// filled last page aside; docs/deploy.md, "The page cache"). So does the recording an
// interrupted run left (a crash, a kill, a power cut), which finish_leftovers() reads through to
// find its cut and place_durably() syncs at the next start: left cached, it would hold up to
// pcap_rotate_bytes (1 GiB) of pcap, and as much MCAP, in memory after every crash.
TEST_CASE("a recording an interrupted run left leaves the page cache once finished at start",
          "[pcap][recovery]") {
  test::ScratchDir dir("recovered-page-cache");
  // Where the pages are the file (tmpfs, ramfs) nothing can leave, and nothing may be lost.
  const bool drops = test::drops_clean_pages(dir.path());
  const fs::path raw = dir / "raw";
  fs::create_directories(raw);
  const fs::path part = raw / "pandarcap_20261129T000000Z_0000.pcap.part";
  // About 5 MiB of whole records, then a record cut in its data, as a killed run leaves it.
  const std::uint64_t whole = write_recording(part, 4000);
  fs::resize_file(part, whole + 700);
  // Written and synced long ago (by the run that died): nothing of it in the cache at start.
  test::drop_from_page_cache(part);
  const auto cached_count = [](const fs::path& file) {
    const std::vector<bool> cached = test::cached_pages(file);
    return static_cast<std::size_t>(std::count(cached.begin(), cached.end(), true));
  };
  if (drops) REQUIRE(cached_count(part) == 0);

  OutputAccounting accounting;
  OutputLeftovers where;
  where.raw_dir = raw;
  finish_leftovers(where, accounting);

  const fs::path finished = raw / "pandarcap_20261129T000000Z_0000.pcap";
  REQUIRE(fs::exists(finished));
  REQUIRE(fs::file_size(finished) == whole);
  // As the finisher leaves a recording it placed: its partly filled last page at most.
  const std::size_t page = static_cast<std::size_t>(::sysconf(_SC_PAGESIZE));
  INFO((whole + page - 1) / page << " pages in all");
  if (drops) CHECK(cached_count(finished) <= 1);
}
