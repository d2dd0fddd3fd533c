// daemon/io: the failures a test machine rarely produces (a write interrupted, a write that takes
// part of its bytes, a full disk), reached through the system-call seam instead of a tmpfs, and
// what the files written through the layer look like afterwards.
#include <fcntl.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <cerrno>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <system_error>
#include <vector>

#include "bench/child_process.hpp"
#include "daemon/arena_memory.hpp"
#include "daemon/io/errors.hpp"
#include "daemon/io/file_creations.hpp"
#include "daemon/io/file_output.hpp"
#include "daemon/io/syscalls.hpp"
#include "daemon/pcap/capture_reader.hpp"
#include "daemon/pcap/pcap_writer.hpp"
#include "daemon/pipeline_types.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
namespace fs = std::filesystem;

namespace {

// The fake kernel's state: plain globals, since the seam holds plain function pointers.
struct FakeDisk {
  std::size_t max_per_write = SIZE_MAX;  // a short write past this many bytes
  bool interrupt_every_other = false;    // EINTR before every second call
  std::size_t space = SIZE_MAX;          // bytes that fit, then ENOSPC
  std::size_t calls = 0;
  std::size_t interrupted = 0;
};
FakeDisk disk;

ssize_t fake_write(int fd, const void* data, std::size_t size) {
  ++disk.calls;
  if (disk.interrupt_every_other && disk.calls % 2 == 1) {
    ++disk.interrupted;
    errno = EINTR;
    return -1;
  }
  if (disk.space == 0) {
    errno = ENOSPC;
    return -1;
  }
  const std::size_t n = std::min({size, disk.max_per_write, disk.space});
  const ssize_t written = ::write(fd, data, n);
  if (written > 0) disk.space -= static_cast<std::size_t>(written);
  return written;
}

io::FileSyscalls fake_calls() {
  io::FileSyscalls calls = io::real_file_syscalls();
  calls.write = fake_write;
  return calls;
}

}  // namespace

TEST_CASE("OutputFile retries interrupted and short writes until every byte is written", "[io]") {
  test::ScratchDir dir("io-short");
  disk = FakeDisk{.max_per_write = 7, .interrupt_every_other = true};
  const io::ScopedFileSyscalls seam(fake_calls());
  std::string text;
  for (int i = 0; i < 100; ++i)
    text += "line " + std::to_string(i) + "\n";
  OutputFile file(dir / "out.txt", OutputFile::Mode::kCreate);
  file.write(text);
  file.close();
  CHECK(harness::read_file(dir / "out.txt") == text);
  CHECK(file.size() == text.size());
  CHECK(disk.interrupted >= text.size() / 7);  // the interruptions did happen, and were retried
}

TEST_CASE("a full disk is a system_error with ENOSPC and the file's name", "[io]") {
  test::ScratchDir dir("io-full");
  disk = FakeDisk{.space = 10};
  const io::ScopedFileSyscalls seam(fake_calls());
  OutputFile file(dir / "full.txt", OutputFile::Mode::kCreate);
  try {
    file.write(std::string(64, 'x'));
    FAIL("the write past the free space did not throw");
  } catch (const std::system_error& error) {
    CHECK(error.code() == std::errc::no_space_on_device);
    CHECK(std::string(error.what()).find("cannot write '" + (dir / "full.txt").string() + "'") !=
          std::string::npos);
  }
  CHECK(file.size() == 10);  // what did reach the file is accounted for
}

TEST_CASE("a recording the disk filled mid-flush is cut back to its last whole flush",
          "[io][pcap]") {
  test::ScratchDir dir("io-pcap");
  const fs::path path = dir / "r.pcap";
  std::vector<char> buffer(4096);
  const std::vector<std::uint8_t> payload(1262, 0xAB);
  constexpr std::int64_t kTime = 1'795'348'800'000'000'000;
  disk = FakeDisk{};
  const io::ScopedFileSyscalls seam(fake_calls());
  PcapWriter writer(path.string(), buffer);
  for (int i = 0; i < 2; ++i)
    writer.write(payload, kTime + i, Endpoint{0x7F000001, 10000}, Endpoint{0x7F000001, 2368});
  writer.flush();
  REQUIRE(writer.flushed_records() == 2);
  // Two more records buffered; the disk then takes only part of them.
  for (int i = 2; i < 4; ++i)
    writer.write(payload, kTime + i, Endpoint{0x7F000001, 10000}, Endpoint{0x7F000001, 2368});
  disk.space = 700;
  CHECK_THROWS_AS(writer.flush(), std::system_error);
  CHECK(fs::file_size(path) > writer.flushed_bytes());  // a cut record reached the file
  const PcapWriter::Dropped dropped = writer.abandon();
  CHECK(dropped.records == 2);
  CHECK(fs::file_size(path) == writer.flushed_bytes());
  // Readable to its end, with exactly the flushed records.
  const auto [status, records] = test::read_capture(path);
  CHECK(status == CaptureStatus::kEnd);
  CHECK(records == 2);
}

TEST_CASE("the seam is put back when the test's scope ends", "[io]") {
  {
    const io::ScopedFileSyscalls seam(fake_calls());
    CHECK(io::file_syscalls().write == &fake_write);
  }
  CHECK(io::file_syscalls().write == io::real_file_syscalls().write);
}

TEST_CASE("throw_errno names what failed, and never reports errno 0 as success", "[io]") {
  errno = 0;
  try {
    io::throw_errno("cannot flush", "x.pcap");
  } catch (const std::system_error& error) {
    CHECK(error.code().value() == EIO);
    CHECK(std::string(error.what()).starts_with("cannot flush 'x.pcap'"));
  }
  errno = EACCES;
  CHECK_THROWS_WITH(io::throw_errno("cannot open"), Catch::Contains("cannot open"));
}

TEST_CASE("OutputFile O_DIRECT: whole aligned blocks past the page cache, then the tail", "[io]") {
  test::ScratchDir dir("io-direct");
  ArenaMemory memory(4 * kDirectIoBlock);  // page-aligned
  const std::span<std::uint8_t> bytes(memory.data(), 3 * kDirectIoBlock + 100);
  for (std::size_t i = 0; i < bytes.size(); ++i)
    bytes[i] = static_cast<std::uint8_t>(i % 251);
  OutputFile file(dir / "direct.bin", OutputFile::Mode::kCreateDirect);
  const bool direct = file.direct();
  file.write(bytes.first(3 * kDirectIoBlock));
  file.end_direct();
  CHECK_FALSE(file.direct());
  file.write(bytes.subspan(3 * kDirectIoBlock));
  file.close();
  CHECK(harness::read_file(dir / "direct.bin") == std::string(bytes.begin(), bytes.end()));
  INFO("O_DIRECT on the scratch directory's file system: " << direct);
}

// Each file created counts once in io::file_creations(), with the CPU its open took; a file
// opened to append, or one that cannot be opened, does not.
TEST_CASE("OutputFile counts the files it creates and the CPU their creation took", "[io]") {
  test::ScratchDir dir("io-file-creations");
  const io::FileCreations& created = io::file_creations();
  const std::uint64_t files_before = created.files.load();
  const std::uint64_t cpu_before = created.cpu_ns.load();
  OutputFile file;
  for (int i = 0; i < 20; ++i)
    file.open((dir / ("f" + std::to_string(i))).native(), OutputFile::Mode::kCreate);
  file.open((dir / "direct").native(), OutputFile::Mode::kCreateDirect);
  CHECK(created.files.load() - files_before == 21);
  CHECK(created.cpu_ns.load() > cpu_before);  // an open is microseconds of a thread's CPU
  file.open((dir / "f0").native(), OutputFile::Mode::kAppend);
  CHECK(file.try_open((dir / "missing" / "f").native(), OutputFile::Mode::kCreate));
  CHECK(created.files.load() - files_before == 21);
}
