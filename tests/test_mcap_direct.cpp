// daemon/mcap past the page cache: every chunk goes to the file in one O_DIRECT write, framed by
// the compression thread (its Chunk record, its MessageIndex records and a Padding record that
// ends it on a 4096-byte block), after opening records padded the same way; the tail goes through
// the page cache. What the tests hold the writer to:
//   - the layout: each chunk starts on a block, each padding ends on one and is zeros, and the
//     MCAP project's reader (which skips the record, as the spec lets an application's) reads
//     every message;
//   - the page cache: none of the data section's pages is cached after the file is closed (a
//     write through the page cache leaves them there until they are dropped);
//   - a file system that takes O_DIRECT at open and refuses the writes: the same file, through
//     the page cache, for that file and those after it;
//   - a file cut before, inside or after a padding record: the recovery keeps every chunk whose
//     indexes are whole.
// McapFile's thread compresses the chunks: every test here is [threads].
#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <catch2/catch.hpp>
#include <cerrno>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <map>
#include <span>
#include <string>
#include <vector>

#include "bench/child_process.hpp"
#include "core/mcap/mcap_parse.hpp"
#include "daemon/io/file_output.hpp"
#include "daemon/io/syscalls.hpp"
#include "daemon/mcap/mcap_file.hpp"
#include "daemon/mcap/mcap_recovery.hpp"
#include "support/mcap_data_records.hpp"
#include "support/mcap_reader.hpp"
#include "support/page_cache.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
namespace fs = std::filesystem;

namespace {

constexpr std::uint64_t kDirectT0 = 1'795'348'800'000'000'000;  // 2026-11-20, ns

McapFileOptions direct_test_options() {
  McapFileOptions o;
  o.compression = mcap::ChunkCompression::kLz4;
  o.chunk_bytes = 64 * 1024;  // a chunk every ~50 packets: dozens per file
  o.max_frame_points = 1000;
  o.max_chunks = 256;
  o.packets = true;
  o.library = "pandarcap test";
  o.calibration_csv = "Channel,Elevation,Azimuth\n1,15,0\n";
  o.wait_for_free_chunk = true;  // every message written: the counts below are exact
  return o;
}

// `packets` datagrams whose bytes differ (so the chunks compress to odd sizes), a flush every 300
// as the writer's tick does (chunks that are not full). Returns the messages written.
std::uint64_t write_direct_packets(McapFile& file, const fs::path& path, int packets) {
  file.open(path.string(), kDirectT0);
  std::vector<std::uint8_t> payload(1262);
  std::uint32_t state = 12345;
  for (int p = 0; p < packets; ++p) {
    for (auto& byte : payload) {
      state = state * 1103515245u + 12345u;
      byte = static_cast<std::uint8_t>(state >> 27);  // 5 bits: lz4 halves it, not more
    }
    const std::uint64_t t = kDirectT0 + static_cast<std::uint64_t>(p) * 277'000;
    REQUIRE(file.add_packet(payload, static_cast<std::int64_t>(t), t));
    if (p % 300 == 299) file.flush();
  }
  file.close();
  return file.messages();
}

struct Layout {
  std::size_t chunks = 0, paddings = 0;
  std::uint64_t data_end = 0;                    // where DataEnd starts
  std::vector<test::DataRecord> chunk_paddings;  // the padding after each chunk's indexes
};

// Walks the data section: every record parses, a chunk starts on a block, each padding is zeros
// and ends on one, and a chunk's indexes are followed by a padding.
Layout walk_blocks(const std::string& bytes) {
  Layout layout;
  mcap::Op last{};
  for (const test::DataRecord& record : test::data_records(bytes)) {
    INFO("record at " << record.at);
    if (record.op == mcap::Op::kChunk) {
      CHECK(record.at % kDirectIoBlock == 0);
      // The first chunk follows the opening records' padding; each next one its chunk's.
      CHECK(last == mcap::Op::kPadding);
      ++layout.chunks;
    } else if (record.op == mcap::Op::kPadding) {
      CHECK(record.end() % kDirectIoBlock == 0);
      CHECK(std::ranges::all_of(record.content, [](std::uint8_t b) { return b == 0; }));
      ++layout.paddings;
      if (layout.chunks > 0) layout.chunk_paddings.push_back(record);
    } else if (record.op == mcap::Op::kDataEnd) {
      CHECK(last == mcap::Op::kPadding);
      layout.data_end = record.at;
    }
    last = record.op;
  }
  return layout;
}

// Whether `dir`'s file system takes O_DIRECT writes (tmpfs before Linux 6.6 does not).
bool takes_direct_writes(const fs::path& dir) {
  const fs::path probe = dir / "direct-probe";
  const int fd = ::open(probe.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_DIRECT | O_CLOEXEC, 0644);
  if (fd < 0) return false;
  void* block = nullptr;
  const bool ok = ::posix_memalign(&block, kDirectIoBlock, kDirectIoBlock) == 0 &&
                  ::write(fd, block, kDirectIoBlock) == static_cast<ssize_t>(kDirectIoBlock);
  std::free(block);
  ::close(fd);
  fs::remove(probe);
  return ok;
}

// A file system that opens with O_DIRECT and refuses its writes (EINVAL), as some FUSE ones do.
int refused_direct_writes = 0;
ssize_t refuse_direct_write(int fd, const void* data, std::size_t size) {
  const int flags = ::fcntl(fd, F_GETFL);
  if (flags >= 0 && (flags & O_DIRECT) != 0) {
    ++refused_direct_writes;
    errno = EINVAL;
    return -1;
  }
  return ::write(fd, data, size);
}

std::uint64_t read_message_count(const fs::path& file) {
  const test::IndependentRead read = test::read_mcap_independently(file);
  INFO(read.error);
  if (read.reader_missing) return 0;
  REQUIRE(read.file.has_value());
  return (*read.file)["statistics"]["message_count"].get<std::uint64_t>();
}

}  // namespace

TEST_CASE("MCAP chunks past the page cache: each on 4096-byte blocks with its indexes and padding",
          "[mcap][threads]") {
  test::ScratchDir dir("mcap-direct");
  const fs::path path = dir / "direct.mcap";
  McapFile file(direct_test_options());
  const std::uint64_t messages = write_direct_packets(file, path, 3000);
  REQUIRE(messages == 3000);
  // Before anything reads the file (a read brings its pages in).
  const std::vector<bool> cached = test::cached_pages(path);
  const std::string bytes = harness::read_file(path);
  const Layout layout = walk_blocks(bytes);
  CHECK(layout.chunks >= 40);
  CHECK(layout.paddings == layout.chunks + 1);  // the opening records' and each chunk's
  const std::uint64_t read = read_message_count(path);
  if (read != 0) CHECK(read == messages);

  // Written past the page cache, none of the data section's pages is in it (the tail, written
  // through it, may be). Through the page cache they all would be, until dropped.
  if (!takes_direct_writes(dir.path())) {
    WARN("the scratch directory's file system takes no O_DIRECT: the page cache not checked");
    return;
  }
  const std::size_t data_pages = layout.data_end / kDirectIoBlock;
  REQUIRE(cached.size() >= data_pages);
  const auto cached_data = std::count(cached.begin(), cached.begin() + data_pages, true);
  INFO(cached_data << " of the data section's " << data_pages << " pages cached");
  CHECK(cached_data == 0);
}

TEST_CASE("MCAP where O_DIRECT opens but its writes are refused: the same file through the cache",
          "[mcap][threads]") {
  test::ScratchDir dir("mcap-direct-refused");
  refused_direct_writes = 0;
  io::FileSyscalls calls = io::real_file_syscalls();
  calls.write = refuse_direct_write;
  const io::ScopedFileSyscalls seam(calls);
  McapFile file(direct_test_options());
  // The first file finds out (one write refused, then every byte through the page cache); the
  // second, a rotation, opens without O_DIRECT.
  for (const char* name : {"first.mcap", "second.mcap"}) {
    INFO(name);
    const fs::path path = dir / name;
    CHECK(write_direct_packets(file, path, 1000) == 1000);
    const Layout layout = walk_blocks(harness::read_file(path));
    CHECK(layout.chunks >= 10);
    const std::uint64_t read = read_message_count(path);
    if (read != 0) CHECK(read == 1000);
  }
  // Zero where the file system has no O_DIRECT at all: then the open said so instead.
  CHECK(refused_direct_writes == (takes_direct_writes(dir.path()) ? 1 : 0));
}

TEST_CASE("a .part cut before inside or after a padding record keeps every chunk before it whole",
          "[mcap][recovery][threads]") {
  test::ScratchDir dir("mcap-direct-cut");
  const fs::path whole = dir / "whole.mcap";
  McapFile file(direct_test_options());
  REQUIRE(write_direct_packets(file, whole, 600) == 600);
  const std::string bytes = harness::read_file(whole);
  const Layout layout = walk_blocks(bytes);
  REQUIRE(layout.chunk_paddings.size() >= 4);
  // The third chunk starts where the second one's padding ended; its own padding follows its
  // indexes and ends on a block.
  const std::uint64_t third = layout.chunk_paddings[1].end();
  const std::uint64_t padding_start = layout.chunk_paddings[2].at;
  const std::uint64_t padding_end = layout.chunk_paddings[2].end();
  REQUIRE(
      mcap::record_at(std::span(reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size())
                          .subspan(third))
          ->op == mcap::Op::kChunk);
  struct Cut {
    const char* where;
    std::uint64_t at;
    int chunks;  // whole chunks kept
  };
  const Cut cuts[] = {
      {"inside the third chunk", third + 100, 2},
      {"where its padding starts", padding_start, 3},
      {"inside its padding's prefix", padding_start + 4, 3},
      {"inside its padding", (padding_start + padding_end) / 2 + 5, 3},
      {"where its padding ends", padding_end, 3},
  };
  std::map<int, std::uint64_t> kept;  // messages kept, by whole chunks kept
  for (const Cut& cut : cuts) {
    INFO(cut.where << " (at " << cut.at << ")");
    const fs::path part = dir / "cut.mcap.part";
    {
      std::ofstream out(part, std::ios::binary | std::ios::trunc);
      out.write(bytes.data(), static_cast<std::streamsize>(cut.at));
    }
    const McapRecovery recovery = finish_interrupted_mcap(part.string());
    CHECK(recovery.ours);
    CHECK(recovery.kept_bytes <= cut.at);
    if (cut.chunks == 3) CHECK(recovery.kept_bytes >= padding_start);
    // Cuts that keep the same chunks keep the same messages.
    const auto [first, inserted] = kept.emplace(cut.chunks, recovery.messages);
    if (!inserted) CHECK(recovery.messages == first->second);
    const std::uint64_t read = read_message_count(part);
    if (read != 0) CHECK(read == recovery.messages);
  }
  // Each cut at or in the padding kept the third chunk; the one inside the chunk did not.
  CHECK(kept[2] > 0);
  CHECK(kept[3] > kept[2]);
}
