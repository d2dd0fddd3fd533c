// daemon/output/file_finisher: the writer's files synced and put in place on a thread of their own
// (durable before visible), and what each part of the writer learns back; the frames' way
// through it, past the page cache.
#include <fcntl.h>
#include <fmt/format.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <catch2/catch.hpp>
#include <cerrno>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "bench/child_process.hpp"
#include "daemon/arena_memory.hpp"
#include "daemon/io/file_output.hpp"
#include "daemon/io/syscalls.hpp"
#include "daemon/output/file_finisher.hpp"
#include "daemon/output/frame_output.hpp"
#include "daemon/output/health_room.hpp"
#include "daemon/output/output_accounting.hpp"
#include "daemon/pipeline_types.hpp"
#include "support/page_cache.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
namespace fs = std::filesystem;

namespace {

// Writes refused with EINVAL while the file is open O_DIRECT, as a file system that takes the
// open but not the writes would.
std::size_t direct_writes = 0, direct_refusals = 0;
bool refuse_direct = false;
ssize_t direct_aware_write(int fd, const void* data, std::size_t size) {
  const int flags = ::fcntl(fd, F_GETFL);
  if (flags >= 0 && (flags & O_DIRECT) != 0) {
    ++direct_writes;
    if (refuse_direct) {
      ++direct_refusals;
      errno = EINVAL;
      return -1;
    }
  }
  return ::write(fd, data, size);
}

// The data section of a PCD file: what follows "DATA binary\n".
std::string pcd_data(const std::string& file) {
  const std::size_t at = file.find("DATA binary\n");
  return at == std::string::npos ? std::string() : file.substr(at + 12);
}

// The writer's part: finished frames go back to the FrameOutput that wrote them.
struct ToFrames final : FinishReceiver {
  FrameOutput* frames = nullptr;
  void finished(const FinishJob& job) override { frames->finished(job); }
};

// Everything the finisher hands back, kept for the test to read.
struct Collected final : FinishReceiver {
  std::vector<FinishJob> jobs;
  void finished(const FinishJob& job) override {
    FinishJob copy;
    copy.kind = job.kind;
    copy.owner = job.owner;
    copy.from = job.from;
    copy.to = job.to;
    copy.bytes = job.bytes;
    copy.items = job.items;
    copy.stamp_ns = job.stamp_ns;
    copy.placed = job.placed;
    copy.name_taken = job.name_taken;
    copy.failed = job.failed;
    copy.error_code = job.error_code;
    copy.error = job.error;
    jobs.push_back(std::move(copy));
  }
};

void write_file(const fs::path& path, std::string_view text) {
  std::ofstream(path, std::ios::binary) << text;
}

// fdatasync through the seam: fails with EIO while `failing_syncs` says so, and counts.
std::atomic<int> syncs{0};
std::atomic<bool> failing_syncs{false};
int counting_fdatasync(int fd) {
  ++syncs;
  if (failing_syncs) {
    errno = EIO;
    return -1;
  }
  return ::fdatasync(fd);
}

}  // namespace

TEST_CASE("the finisher syncs, then renames without replacing, and says what it did",
          "[io][threads]") {
  test::ScratchDir dir("finisher-place");
  Collected receiver;
  io::FileSyscalls calls = io::real_file_syscalls();
  calls.fdatasync = counting_fdatasync;
  const io::ScopedFileSyscalls seam(calls);
  syncs = 0;
  failing_syncs = false;
  {
    FileFinisher finisher(receiver, 4);
    // More jobs than the finisher holds: take() waits for one to come back.
    for (int i = 0; i < 10; ++i) {
      const fs::path from = dir / fmt::format(".f{}.tmp", i), to = dir / fmt::format("f{}", i);
      write_file(from, fmt::format("file {}", i));
      FinishJob& job = finisher.take();
      job.kind = FinishJob::Kind::kPlace;
      job.owner = FinishOwner::kRecordings;
      job.from = from.native();
      job.to = to.native();
      job.items = static_cast<std::uint64_t>(i);
      finisher.submit(job);
      CHECK(finisher.in_flight() <= 4);
    }
    // A name that is taken: kept under "_dup1", never over the file there.
    write_file(dir / "taken.pcap", "first");
    write_file(dir / ".taken.pcap.tmp", "second");
    FinishJob& taken = finisher.take();
    taken.kind = FinishJob::Kind::kPlace;
    taken.from = (dir / ".taken.pcap.tmp").native();
    taken.to = (dir / "taken.pcap").native();
    finisher.submit(taken);
    // A file replaced whole (health's .prom).
    write_file(dir / "health.prom", "old");
    write_file(dir / ".health.prom.tmp", "new");
    FinishJob& replace = finisher.take();
    replace.kind = FinishJob::Kind::kReplace;
    replace.owner = FinishOwner::kHealth;
    replace.from = (dir / ".health.prom.tmp").native();
    replace.to = (dir / "health.prom").native();
    finisher.submit(replace);
    // A file synced where it is; and one that is not there.
    FinishJob& sync = finisher.take();
    sync.from = (dir / "f0").native();
    sync.sync_directory = true;
    finisher.submit(sync);
    FinishJob& missing = finisher.take();
    missing.from = (dir / "missing").native();
    finisher.submit(missing);
    finisher.drain();
    CHECK(finisher.in_flight() == 0);
  }
  REQUIRE(receiver.jobs.size() == 14);
  for (int i = 0; i < 10; ++i) {
    const FinishJob& job = receiver.jobs[static_cast<std::size_t>(i)];  // in the order submitted
    CHECK(job.placed);
    CHECK_FALSE(job.failed);
    CHECK(job.items == static_cast<std::uint64_t>(i));
    CHECK(harness::read_file(job.to) == fmt::format("file {}", i));
    CHECK_FALSE(fs::exists(job.from));
  }
  CHECK(receiver.jobs[10].name_taken);
  CHECK(receiver.jobs[10].to == (dir / "taken_dup1.pcap").native());
  CHECK(harness::read_file(dir / "taken.pcap") == "first");
  CHECK(harness::read_file(dir / "taken_dup1.pcap") == "second");
  CHECK(receiver.jobs[11].placed);
  CHECK(harness::read_file(dir / "health.prom") == "new");
  CHECK_FALSE(receiver.jobs[12].failed);
  CHECK(receiver.jobs[13].failed);
  CHECK(receiver.jobs[13].error_code == ENOENT);
  // Every file's data was synced before it was renamed or reported: 10 + 2 + 1 (the missing one
  // never reached fdatasync).
  CHECK(syncs == 13);
}

TEST_CASE("a sync that fails keeps the file from its final name", "[io][threads]") {
  test::ScratchDir dir("finisher-eio");
  Collected receiver;
  io::FileSyscalls calls = io::real_file_syscalls();
  calls.fdatasync = counting_fdatasync;
  const io::ScopedFileSyscalls seam(calls);
  failing_syncs = true;
  {
    FileFinisher finisher(receiver);
    for (const bool remove : {true, false}) {
      const fs::path from = dir / (remove ? ".frame.pcd.tmp" : "rec.pcap.part");
      write_file(from, "data");
      FinishJob& job = finisher.take();
      job.kind = FinishJob::Kind::kPlace;
      job.from = from.native();
      job.to = (dir / (remove ? "frame.pcd" : "rec.pcap")).native();
      job.remove_on_failure = remove;
      finisher.submit(job);
    }
    finisher.drain();
  }
  failing_syncs = false;
  REQUIRE(receiver.jobs.size() == 2);
  for (const FinishJob& job : receiver.jobs) {
    CHECK(job.failed);
    CHECK_FALSE(job.placed);
    CHECK(job.error_code == EIO);
    CHECK(std::string(job.error_text()).find("cannot sync") != std::string::npos);
    CHECK_FALSE(fs::exists(job.to));
  }
  CHECK_FALSE(fs::exists(receiver.jobs[0].from));  // a frame's temporary file: removed
  CHECK(fs::exists(receiver.jobs[1].from));        // a recording's .part: for the next start
}

TEST_CASE("frames go past the page cache, and through it once a file system refuses that",
          "[io][outputs][threads]") {
  test::ScratchDir dir("io-direct-frames");
  WriterOptions options;
  options.output_dir = dir / "out";
  options.pcd_format = PcdFormat{PcdLayout::kPcl, Axes::kHesai};
  fs::create_directories(options.output_dir / "frames");
  fs::create_directories(options.output_dir / "health");
  OutputAccounting accounting;
  HealthRoom space(options.output_dir / "health");
  ToFrames receiver;
  FileFinisher finisher(receiver);
  FrameOutput output(options, accounting, space, finisher);
  receiver.frames = &output;
  ArenaMemory memory(FrameArena::bytes_for(2000, options.pcd_format));
  FrameArena arena(memory.data(), 2000, options.pcd_format);
  arena.frame.size = 1500;  // 40 500 bytes: 9 whole blocks and a tail
  arena.frame.info.start_ns = 1'795'348'800'000'000'000;
  const auto rows = arena.frame.encoded.first(arena.frame.used_bytes().size());
  for (std::size_t i = 0; i < rows.size(); ++i)
    rows[i] = static_cast<std::uint8_t>(i * 7 % 253);
  const std::string expected(rows.begin(), rows.end());

  io::FileSyscalls calls = io::real_file_syscalls();
  calls.write = direct_aware_write;
  const io::ScopedFileSyscalls seam(calls);
  direct_writes = direct_refusals = 0;
  refuse_direct = false;
  for (int round = 0; round < 3; ++round) {
    INFO("round " << round);
    // Round 1: the file system starts refusing direct writes (after opening with O_DIRECT).
    refuse_direct = round >= 1;
    const std::size_t refusals_before = direct_refusals;
    arena.frame.info.sequence = static_cast<std::uint64_t>(round);
    output.write(arena);
    finisher.drain();
    CHECK(accounting.write_errors() == 0);
    CHECK(output.frames_written() == static_cast<std::uint64_t>(round + 1));
    const auto files = test::files_ending(options.output_dir / "frames", ".pcd");
    REQUIRE(files.size() == static_cast<std::size_t>(round + 1));
    const std::string file = harness::read_file(files.back());
    CHECK(pcd_data(file) == expected);  // every point, whichever way it went
    const std::size_t header = file.size() - expected.size();
    if (round == 0 && direct_writes > 0) CHECK(header == kDirectIoBlock);  // padded
    if (round == 2) CHECK(direct_refusals == refusals_before);             // not tried again
  }
  CHECK(output.bytes_written() == 3 * expected.size() + 0 + [&] {
    std::uintmax_t headers = 0;
    for (const auto& f : test::files_ending(options.output_dir / "frames", ".pcd"))
      headers += fs::file_size(f) - expected.size();
    return headers;
  }());
}

TEST_CASE("once synced the recordings leave the page cache and the health files stay in it",
          "[io][threads]") {
  test::ScratchDir dir("finisher-page-cache");
  // Where the pages are the file (tmpfs, ramfs) nothing can be dropped: they must all stay.
  const bool drops = test::drops_clean_pages(dir.path());
  Collected receiver;
  const std::string block(1 << 20, 'r');
  // A recording in progress (synced where it is), one finished (placed), an MCAP file, a frame
  // through the page cache (a file system without O_DIRECT), and the health's appended lines.
  // `tail`: bytes past 4 MiB, so the file ends in a partly filled page, which a recording still
  // being written appends to next: it stays (else the next write reads it back from the disk).
  struct Case {
    const char* name;
    FinishOwner owner;
    FinishJob::Kind kind;
    bool dropped;
    std::size_t tail;
  };
  const Case cases[] = {
      {"rec.pcap.part", FinishOwner::kRecordings, FinishJob::Kind::kSync, true, 100},
      {".done.pcap.tmp", FinishOwner::kRecordings, FinishJob::Kind::kPlace, true, 0},
      {"run.mcap.part", FinishOwner::kMcap, FinishJob::Kind::kSync, true, 4095},
      {".frame.pcd.tmp", FinishOwner::kFrames, FinishJob::Kind::kPlace, true, 1},
      {"health.jsonl", FinishOwner::kHealth, FinishJob::Kind::kSync, false, 100},
      {".health.prom.tmp", FinishOwner::kHealth, FinishJob::Kind::kReplace, false, 0},
  };
  const std::size_t page = static_cast<std::size_t>(::sysconf(_SC_PAGESIZE));
  const auto whole_pages = static_cast<std::ptrdiff_t>(4 * block.size() / page);
  // Whether each file's partly filled last page was counted cached before the sync: mincore()
  // does not count one where the file system's blocks are smaller than a page.
  std::vector<bool> tail_cached;
  for (const Case& c : cases) {
    OutputFile file(dir / c.name, OutputFile::Mode::kCreate);
    for (int i = 0; i < 4; ++i)
      file.write(std::string_view(block));
    file.write(std::string_view(block).substr(0, c.tail));
    file.close();
    // Just written through the page cache: there (and dirty) before any sync.
    const std::vector<bool> cached = test::cached_pages(dir / c.name);
    INFO(c.name);
    REQUIRE(cached.size() == (4 * block.size() + c.tail + page - 1) / page);
    REQUIRE(std::count(cached.begin(), cached.begin() + whole_pages, true) == whole_pages);
    tail_cached.push_back(c.tail > 0 && cached.back());
  }
  {
    FileFinisher finisher(receiver, 8);
    for (const Case& c : cases) {
      FinishJob& job = finisher.take();
      job.kind = c.kind;
      job.owner = c.owner;
      job.from = (dir / c.name).native();
      if (c.kind != FinishJob::Kind::kSync) {
        std::string to = c.name;
        to.erase(0, 1);
        to.erase(to.size() - 4);  // ".done.pcap.tmp" -> "done.pcap"
        job.to = (dir / to).native();
      }
      finisher.submit(job);
    }
    finisher.drain();
  }
  REQUIRE(receiver.jobs.size() == std::size(cases));
  for (std::size_t i = 0; i < std::size(cases); ++i) {
    const Case& c = cases[i];
    const FinishJob& job = receiver.jobs[i];
    INFO(c.name << (drops ? "" : " (a file system that keeps its pages)"));
    REQUIRE_FALSE(job.failed);
    const fs::path now = job.to.empty() ? fs::path(job.from) : fs::path(job.to);
    const std::vector<bool> cached = test::cached_pages(now);
    const auto whole_cached = std::count(cached.begin(), cached.begin() + whole_pages, true);
    CHECK(whole_cached == (c.dropped && drops ? 0 : whole_pages));
    // The partly filled last page stays, where it could be seen before.
    if (tail_cached[i]) CHECK(cached.back());
    // A recording still being written goes on at its partly filled last page: from the cache,
    // not read back from the disk first (this process's storage reads do not grow).
    std::size_t appended = 0;
    if (c.kind == FinishJob::Kind::kSync && c.tail > 0) {
      const std::uint64_t read_before = test::storage_bytes_read();
      OutputFile file(now, OutputFile::Mode::kAppend);
      file.write(std::string_view(block).substr(0, 10));
      file.close();
      appended = 10;
      CHECK(test::storage_bytes_read() == read_before);
    }
    // Nothing lost, whatever was dropped (read after the look: reading caches it again).
    CHECK(harness::read_file(now) == std::string(4 * block.size() + c.tail + appended, 'r'));
  }
}

// The test above tells "pages that cannot be dropped" by TMPFS_MAGIC alone. Where the scratch
// directory (TMPDIR) is on another file system whose pages are the file, nothing can be dropped
// either, and the product keeps every page (correct: nothing lost), but that test then expects the
// whole pages gone and fails: a ramfs TMPDIR, or an overlay whose upper layer is a tmpfs (a
// container's /tmp on a RAM-backed overlay). And it counts a page as cached only when mincore()
// says so, which a page partly written on a file system with blocks smaller than a page never is
// (ext4 with 1 KiB blocks; 4 KiB blocks under 64 KiB pages): it fails before any sync there.
// The suite must pass wherever TMPDIR is.
TEST_CASE(
    "the page cache test passes with TMPDIR on ramfs or an overlay over tmpfs or small-block ext4",
    "[io]") {
  const std::string userns = ::geteuid() == 0 ? "" : "--user --map-root-user ";
  if (test::run_command("unshare " + userns + "--mount true 2>/dev/null").exit_code != 0) {
    WARN("no mount namespace here: not tried");
    return;
  }
  test::ScratchDir dir("finisher-ram-tmpdir");
  const fs::path mount_point = dir / "tmp";
  fs::create_directories(mount_point);
  const std::string inner =
      "'once synced the recordings leave the page cache and the health files stay in it'";
  // Each: its name, the mount at $0, and the directory there that TMPDIR names.
  struct FileSystem {
    const char* name;
    const char* mount;
    const char* tmpdir;
  };
  const FileSystem file_systems[] = {
      {"ramfs", "mount -t ramfs pandarcap-test \"$0\"", "$0"},
      {"overlay over tmpfs",
       "mount -t tmpfs -o size=64m pandarcap-test \"$0\" && mkdir \"$0/l\" \"$0/u\" \"$0/w\" "
       "\"$0/o\" && mount -t overlay pandarcap-test -o "
       "lowerdir=\"$0/l\",upperdir=\"$0/u\",workdir=\"$0/w\" \"$0/o\"",
       "$0/o"},
      // Blocks smaller than a page (mke2fs's choice for a small file system, and any 4 KiB-block
      // ext4 under a 64 KiB-page kernel): a page partly written is cached but not up to date as
      // a whole, so mincore() does not count it, though the append after reads nothing back.
      {"ext4 with 1 KiB blocks",
       "truncate -s 128M \"$0.img\" && mkfs.ext4 -q -F -b 1024 \"$0.img\" && mount -o loop "
       "\"$0.img\" \"$0\"",
       "$0"},
  };
  for (const FileSystem& fs_case : file_systems) {
    INFO(fs_case.name);
    // A loop device needs root itself (not a user namespace's) and mkfs.ext4.
    if (std::string_view(fs_case.name).starts_with("ext4") &&
        (::geteuid() != 0 || test::run_command("command -v mkfs.ext4 >/dev/null").exit_code != 0))
      continue;
    const test::CommandResult result =
        test::run_command("unshare " + userns + "--mount --propagation private -- /bin/sh -c '" +
                          [&] {
                            // The mount, then the test with TMPDIR there ($0: the mount point).
                            const std::string script = std::string(fs_case.mount) +
                                                       " && TMPDIR=\"" + fs_case.tmpdir +
                                                       "\" exec \"$1\" \"$2\"";
                            std::string escaped;
                            for (const char c : script)
                              escaped += c == '\'' ? std::string("'\\''") : std::string(1, c);
                            return escaped;
                          }() +
                          "' " + test::quoted(mount_point) + " " +
                          test::quoted(test::binary("pandarcap_tests")) + " " + inner + " 2>&1");
    INFO(result.out);
    CHECK(result.exit_code == 0);
  }
}
