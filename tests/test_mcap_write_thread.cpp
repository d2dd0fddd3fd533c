// daemon/mcap's write thread ("pc-mcap-write", chunk_pipeline.hpp): the chunks reach the file on
// a thread of their own, so a slow or stalled MCAP disk never holds the writer thread, which
// writes the frames and the pcap too. What the tests hold it to:
//   - a stalled write: the writer's every call returns while the write thread is held inside the
//     file's write(); what no chunk buffer could take is left out and counted; once the disk
//     moves, the file holds every message the writer was told was taken, and only those;
//   - a failed write (ENOSPC on the Nth chunk): the writer is told (std::system_error with the
//     errno), nothing of that file is written after it, abandon() leaves the chunks before it,
//     whole, and the next file is written in full;
//   - every chunk's bytes are written by that thread, none by the writer's;
//   - the recorder, when a chunk write fails and the disk stays full so that the file cannot be
//     finished either: the .part's messages still count as written (the next start finishes
//     it), never falling back, and the bytes lost count as not written;
//   - a rotation while a chunk write is held (SIGHUP's): it returns, and the writer goes on with
//     the next file, while the write is still held; the file left is finished once the disk
//     moves (or cut back when its next chunk write fails, or left for the next start when the
//     disk stays full), and every message is counted once; the next file lost meanwhile (its
//     .part removed) is let go without waiting for the file before.
// The stall is the test seam's write (daemon/io/syscalls.hpp) holding the calls made for the
// MCAP file (known by its inode) until the test lets them go, waited for on a condition with a
// timeout: a writer that wrote the chunks itself would wait there, and fail the test, not hang it.
#include <pthread.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <catch2/catch.hpp>
#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <mutex>
#include <string>
#include <system_error>
#include <vector>

#include "bench/child_process.hpp"
#include "daemon/io/syscalls.hpp"
#include "daemon/mcap/mcap_file.hpp"
#include "daemon/mcap/mcap_recovery.hpp"
#include "daemon/output/file_finisher.hpp"
#include "daemon/output/health_room.hpp"
#include "daemon/output/mcap_recorder.hpp"
#include "daemon/output/output_accounting.hpp"
#include "daemon/output/writer_options.hpp"
#include "support/mcap_data_records.hpp"
#include "support/mcap_reader.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
namespace fs = std::filesystem;

namespace {

constexpr std::uint64_t kWriteT0 = 1'795'348'800'000'000'000;  // 2026-11-20, ns

// The seam's view of the MCAP file's writes: which file, whether they are held, and what came.
struct McapWrites {
  std::mutex mutex;
  std::condition_variable changed;
  ino_t inode = 0;             // the MCAP file's (0: none watched)
  bool hold = false;           // writes wait while set
  int fail_at = 0;             // the Nth write fails with ENOSPC (0: none)
  bool stays_full = false;     // and every one after it (the disk stays full)
  int writes = 0;              // calls for the file, held ones included
  int held = 0;                // waiting in the seam now
  int from_other_threads = 0;  // calls not made by "pc-mcap-write" (after the opening records)
  int after_failure = 0;       // calls after the failed one
  bool timed_out = false;      // a held write waited past the test's patience
};
McapWrites mcap_writes;

bool is_watched(int fd) {
  struct stat st {};
  return ::fstat(fd, &st) == 0 && st.st_ino == mcap_writes.inode;
}

ssize_t watching_write(int fd, const void* data, std::size_t size) {
  {
    std::unique_lock lock(mcap_writes.mutex);
    if (mcap_writes.inode != 0 && is_watched(fd)) {
      char name[16] = {};
      pthread_getname_np(pthread_self(), name, sizeof name);
      if (std::string(name) != "pc-mcap-write") ++mcap_writes.from_other_threads;
      const int n = ++mcap_writes.writes;
      if (mcap_writes.fail_at != 0 && n > mcap_writes.fail_at) ++mcap_writes.after_failure;
      if (n == mcap_writes.fail_at ||
          (mcap_writes.stays_full && n > mcap_writes.fail_at && mcap_writes.fail_at != 0)) {
        errno = ENOSPC;
        return -1;
      }
      ++mcap_writes.held;
      mcap_writes.changed.notify_all();
      // Long enough for any machine. A writer thread waiting here ends the hold for good: the
      // test fails on timed_out instead of waiting once per chunk.
      if (!mcap_writes.timed_out &&
          !mcap_writes.changed.wait_for(lock, std::chrono::seconds(30),
                                        [] { return !mcap_writes.hold; })) {
        mcap_writes.timed_out = true;
      }
      --mcap_writes.held;
    }
  }
  return ::write(fd, data, size);
}

// The real calls, but write(): the seam's view above.
io::FileSyscalls watching_calls() {
  io::FileSyscalls calls = io::real_file_syscalls();
  calls.write = watching_write;
  return calls;
}

// Starts watching `path`'s writes (made after its opening records).
void watch(const fs::path& path, bool hold, int fail_at, bool stays_full = false) {
  std::lock_guard lock(mcap_writes.mutex);
  struct stat st {};
  REQUIRE(::stat(path.c_str(), &st) == 0);
  mcap_writes.inode = st.st_ino;
  mcap_writes.hold = hold;
  mcap_writes.fail_at = fail_at;
  mcap_writes.stays_full = stays_full;
  mcap_writes.writes = mcap_writes.held = mcap_writes.from_other_threads = 0;
  mcap_writes.after_failure = 0;
  mcap_writes.timed_out = false;
}

void release_writes() {
  std::lock_guard lock(mcap_writes.mutex);
  mcap_writes.hold = false;
  mcap_writes.changed.notify_all();
}

McapFileOptions write_thread_options() {
  McapFileOptions o;
  o.compression = mcap::ChunkCompression::kLz4;
  o.chunk_bytes = 64 * 1024;  // a chunk every ~50 packets
  o.chunk_buffers = 3;        // the daemon's default pool
  o.max_frame_points = 1000;
  o.max_chunks = 512;
  o.packets = true;
  o.library = "pandarcap test";
  o.calibration_csv = "Channel,Elevation,Azimuth\n1,15,0\n";
  o.wait_for_free_chunk = false;  // live: never wait for a buffer
  return o;
}

// A datagram whose bytes differ from the last one's (chunks compress to odd sizes).
const std::vector<std::uint8_t>& next_payload() {
  static std::vector<std::uint8_t> payload(1262);
  static std::uint32_t state = 12345;
  for (auto& byte : payload) {
    state = state * 1103515245u + 12345u;
    byte = static_cast<std::uint8_t>(state >> 27);
  }
  return payload;
}

// `packets` datagrams into the open file, a flush every 300 as the writer's tick does. Returns
// how many were taken (add_packet said so).
std::uint64_t add_packets(McapFile& file, int packets, int first) {
  std::uint64_t taken = 0;
  for (int p = first; p < first + packets; ++p) {
    const std::uint64_t t = kWriteT0 + static_cast<std::uint64_t>(p) * 277'000;
    taken += file.add_packet(next_payload(), static_cast<std::int64_t>(t), t) ? 1 : 0;
    if (p % 300 == 299) file.flush();
  }
  return taken;
}

}  // namespace

TEST_CASE("a stalled MCAP disk holds only MCAP: the writer never waits and counts what it left out",
          "[mcap][threads]") {
  const io::ScopedFileSyscalls seam(watching_calls());
  test::ScratchDir dir("mcap-write-stall");
  const fs::path path = dir / "a.mcap";
  McapFile file(write_thread_options());
  file.open(path.string(), kWriteT0);
  const auto opening_bytes = fs::file_size(path);
  watch(path, /*hold=*/true, /*fail_at=*/0);

  // 3000 packets (~60 chunks) while the disk takes nothing: the first chunk's write is held, the
  // pool's other buffers fill behind it, and then every message is left out at once.
  const std::uint64_t taken_while_held = add_packets(file, 3000, 0);
  {
    std::unique_lock lock(mcap_writes.mutex);
    REQUIRE(mcap_writes.changed.wait_for(lock, std::chrono::seconds(30),
                                         [] { return mcap_writes.held == 1; }));
    CHECK(mcap_writes.writes == 1);  // the rest wait behind it, unwritten
  }
  CHECK(fs::file_size(path) == opening_bytes);
  CHECK(taken_while_held > 0);
  CHECK(taken_while_held < 3000 / 4);  // three buffers' worth, not the 3000
  CHECK(file.messages_not_recorded() == 3000 - taken_while_held);
  CHECK(file.messages() == 0);  // none back yet: none counted as in the file

  // The disk moves again: the chunks held come back written, and new messages are taken.
  release_writes();
  const std::uint64_t taken_after = add_packets(file, 600, 3000);
  file.close();
  const std::uint64_t taken = taken_while_held + taken_after;
  CHECK(file.messages() == taken);
  CHECK(file.messages_not_recorded() + taken == 3600);
  {
    std::lock_guard lock(mcap_writes.mutex);
    CHECK_FALSE(mcap_writes.timed_out);
    CHECK(mcap_writes.from_other_threads == 1);  // the tail, close()'s: every chunk was not
    mcap_writes.inode = 0;
  }
  CHECK(finish_interrupted_mcap(path.string()).messages == taken);  // a finished file, all kept
  const auto read = test::read_mcap_independently(path);
  if (read.reader_missing) return;
  INFO(read.error);
  REQUIRE(read.file);
  CHECK((*read.file)["statistics"]["message_count"].get<std::uint64_t>() == taken);
}

TEST_CASE(
    "a chunk write that fails: the writer told, nothing after it written, the next file whole",
    "[mcap][threads]") {
  const int fail_at = GENERATE(1, 2, 5);
  INFO("the chunk write that fails: #" << fail_at);
  const io::ScopedFileSyscalls seam(watching_calls());
  test::ScratchDir dir("mcap-write-fails");
  const fs::path path = dir / "a.mcap.part";
  McapFileOptions options = write_thread_options();
  options.wait_for_free_chunk = true;  // every message handed over: the failure must come
  McapFile file(options);
  file.open(path.string(), kWriteT0);
  watch(path, /*hold=*/false, fail_at);

  int code = 0;
  try {
    add_packets(file, 3000, 0);
    file.close();
  } catch (const std::system_error& error) {
    code = error.code().value();
  }
  CHECK(code == ENOSPC);
  const std::uint64_t lost = file.abandon();
  CHECK(lost > 0);
  {
    std::lock_guard lock(mcap_writes.mutex);
    CHECK(mcap_writes.after_failure == 0);  // no chunk of the file written after the failure
    CHECK(mcap_writes.from_other_threads == 0);
    mcap_writes.inode = 0;
  }
  // The file ends on the chunks written before the failure, each whole with its indexes.
  std::size_t chunks = 0;
  for (const test::DataRecord& record :
       test::data_records(harness::read_file(path), test::WalkTo::kFileEnd))
    chunks += record.op == mcap::Op::kChunk ? 1 : 0;
  CHECK(chunks == static_cast<std::size_t>(fail_at - 1));
  CHECK(fs::file_size(path) % kDirectIoBlock == 0);  // on a chunk's padding, or the opening's
  const McapRecovery recovered = finish_interrupted_mcap(path.string());
  CHECK(recovered.cut_bytes == 0);
  CHECK(recovered.messages == file.messages());  // the messages of the chunks written

  // The same McapFile's next file: its writes are its own, written in full.
  const fs::path next = dir / "b.mcap";
  file.open(next.string(), kWriteT0);
  const std::uint64_t taken = add_packets(file, 1000, 0);
  file.close();
  CHECK(taken == 1000);
  CHECK(file.messages() == 1000);
  CHECK(finish_interrupted_mcap(next.string()).messages == 1000);
}

namespace {

// The finisher's word, to the recorder (as the writer passes it on).
struct ToRecorder final : FinishReceiver {
  McapRecorder* recorder = nullptr;
  void finished(const FinishJob& job) override { recorder->finished(job); }
};

// Waits (with a timeout) until the seam holds a write of the watched file.
bool write_held() {
  std::unique_lock lock(mcap_writes.mutex);
  return mcap_writes.changed.wait_for(lock, std::chrono::seconds(30),
                                      [] { return mcap_writes.held == 1; });
}

// A real McapRecorder in a scratch output directory, as the writer thread drives it: batches of
// 100 datagrams, a flush after each.
struct RecorderRig {
  test::ScratchDir dir;
  WriterOptions options;
  OutputAccounting accounting;
  std::unique_ptr<HealthRoom> space;
  ToRecorder receiver;
  std::unique_ptr<FileFinisher> finisher;
  std::unique_ptr<McapRecorder> recorder;
  RawBatch batch{100};
  std::uint64_t sent = 0;

  explicit RecorderRig(const char* name, std::size_t chunk_buffers = 3) : dir(name) {
    options.output_dir = dir / "out";
    options.mcap = true;
    options.mcap_file = write_thread_options();
    options.mcap_file.chunk_buffers = chunk_buffers;
    fs::create_directories(options.output_dir / "mcap");
    fs::create_directories(options.output_dir / "health");
    space = std::make_unique<HealthRoom>(options.output_dir / "health");
    finisher = std::make_unique<FileFinisher>(receiver);
    recorder = std::make_unique<McapRecorder>(options, accounting, *space, *finisher);
    receiver.recorder = recorder.get();
    recorder->adopt_earlier_files();
    recorder->prepare();
  }
  ~RecorderRig() {
    recorder->close();
    finisher->drain();
  }
  void send_batch() {
    batch.size = batch.capacity;
    for (std::size_t i = 0; i < batch.size; ++i) {
      RawPacket& packet = batch.packets[i];
      const auto& payload = next_payload();
      std::copy(payload.begin(), payload.end(), packet.payload);
      packet.length = static_cast<std::uint16_t>(payload.size());
      packet.receive_time_ns = static_cast<std::int64_t>(kWriteT0 + sent++ * 277'000);
    }
    recorder->write_packets(batch);
    recorder->flush();
  }
  std::vector<fs::path> files(const char* ending) const {
    return test::files_ending(options.output_dir / "mcap", ending);
  }
  // 1000 datagrams, the first chunk's write held by the seam (watch()) before they are all in.
  void send_until_held() {
    while (sent < 1000)
      send_batch();
    REQUIRE(write_held());
  }
  // The first file, its first chunk write held by the seam after one more batch (two chunks):
  // a pool of more than 3 buffers keeps room for the next file's chunks.
  fs::path hold_first_write() {
    const fs::path first = first_part();
    watch(first, /*hold=*/true, /*fail_at=*/0);
    send_batch();
    REQUIRE(write_held());
    return first;
  }
  // The disk moves again: one more batch, every chunk back and every file settled; no held
  // write timed out meanwhile, and the seam watches no file from here on.
  void release_and_settle() {
    release_writes();
    send_batch();
    recorder->drain();
    finisher->drain();
    std::lock_guard lock(mcap_writes.mutex);
    CHECK_FALSE(mcap_writes.timed_out);
    mcap_writes.inode = 0;
  }
  // The first batch: the file it opens (the only .part).
  fs::path first_part() {
    send_batch();
    const std::vector<fs::path> parts = files(".mcap.part");
    REQUIRE(parts.size() == 1);
    return parts.front();
  }
  // Every datagram sent is written, left out (no chunk buffer free) or not written (a
  // failure): never two of these, never none.
  std::uint64_t accounted() const {
    return recorder->messages_written() + recorder->messages_not_written() +
           recorder->messages_not_recorded();
  }
};

}  // namespace

TEST_CASE("a chunk write fails and the disk stays full: the .part's messages still written",
          "[mcap][outputs][threads]") {
  const io::ScopedFileSyscalls seam(watching_calls());
  RecorderRig rig("mcap-stays-full");
  McapRecorder& recorder = *rig.recorder;
  const fs::path part = rig.first_part();
  // The 4th chunk write fails, and so does every write to the file after it: the recovery's
  // tail too, so the file stays a .part.
  watch(part, /*hold=*/false, /*fail_at=*/4, /*stays_full=*/true);
  std::uint64_t written_before = 0;
  for (int round = 0; round < 100 && rig.accounting.write_errors() == 0; ++round) {
    rig.send_batch();
    CHECK(recorder.messages_written() >= written_before);
    written_before = recorder.messages_written();
  }
  REQUIRE(rig.accounting.write_errors() > 0);
  CHECK(recorder.messages_written() >= written_before);  // never back, at the failure either
  CHECK(rig.accounting.bytes_not_written() > 0);         // the chunks lost, in bytes
  CHECK(recorder.messages_not_written() > 0);
  {
    std::lock_guard lock(mcap_writes.mutex);
    mcap_writes.inode = 0;  // the disk has room again
  }
  REQUIRE(fs::exists(part));  // not finished: the disk was full
  // What the next start finishes is what was counted as written: the three chunks before it.
  const McapRecovery recovered = finish_interrupted_mcap(part.string());
  CHECK(recovered.messages > 0);
  CHECK(recorder.messages_written() == recovered.messages);
}

TEST_CASE("a rotation while the MCAP disk is stalled returns at once: the file left finishes later",
          "[mcap][outputs][threads]") {
  // How the file left behind ends: its chunks written once the disk moves, or a chunk write of
  // it failing then (ENOSPC), with the disk full for its recovery too or not.
  enum class Ending { kWritten, kChunkFails, kChunkFailsStaysFull };
  const Ending ending =
      GENERATE(Ending::kWritten, Ending::kChunkFails, Ending::kChunkFailsStaysFull);
  INFO("ending " << static_cast<int>(ending));
  const io::ScopedFileSyscalls seam(watching_calls());
  RecorderRig rig("mcap-rotate-stall");
  McapRecorder& recorder = *rig.recorder;
  const fs::path first = rig.first_part();
  // Its first chunk write is held; with a failing ending its second fails.
  const bool fails = ending != Ending::kWritten;
  watch(first, /*hold=*/true, /*fail_at=*/fails ? 2 : 0,
        /*stays_full=*/ending == Ending::kChunkFailsStaysFull);
  rig.send_until_held();
  const std::uint64_t written_before = recorder.messages_written();

  // SIGHUP's rotation: it returns while the write is still held (a rotation that waited would
  // sit in the seam until its 30 s timeout, and timed_out would say so).
  recorder.rotate();
  {
    std::lock_guard lock(mcap_writes.mutex);
    CHECK(mcap_writes.held == 1);
    CHECK_FALSE(mcap_writes.timed_out);
  }
  // The writer goes on: a new file opens for the next messages while the first is still held.
  for (int round = 0; round < 5; ++round)
    rig.send_batch();
  CHECK(rig.files(".mcap.part").size() == 2);
  CHECK(recorder.messages_written() >= written_before);
  CHECK(rig.accounted() <= rig.sent);  // those in flight are not yet counted
  {
    std::lock_guard lock(mcap_writes.mutex);
    CHECK(mcap_writes.held == 1);  // still: none of the above waited for the disk
    CHECK_FALSE(mcap_writes.timed_out);
  }

  release_writes();
  for (int round = 0; round < 5; ++round)
    rig.send_batch();
  recorder.drain();  // every chunk in flight back: the first file settled too
  rig.finisher->drain();
  CHECK(rig.accounted() == rig.sent);
  CHECK(recorder.messages_written() >= written_before);
  if (fails) {
    CHECK(rig.accounting.write_errors() > 0);
    CHECK(recorder.messages_not_written() > 0);
  } else {
    CHECK(recorder.messages_not_written() == 0);
    CHECK(rig.accounting.write_errors() == 0);
  }
  {
    std::lock_guard lock(mcap_writes.mutex);
    CHECK_FALSE(mcap_writes.timed_out);
    mcap_writes.inode = 0;  // the disk has room again
  }
  const std::uint64_t written = recorder.messages_written();
  // The first file: in place under its final name, or, when the disk stayed full, a .part that
  // the next start finishes with what was counted.
  std::uint64_t on_disk = 0;
  fs::path placed;
  if (ending == Ending::kChunkFailsStaysFull) {
    REQUIRE(fs::exists(first));
    on_disk += finish_interrupted_mcap(first.string()).messages;
  } else {
    CHECK_FALSE(fs::exists(first));
    REQUIRE(rig.files(".mcap").size() == 1);
    placed = rig.files(".mcap").front();
    // Finished: a reader of its own accepts it, with the count its summary gives.
    const auto read = test::read_mcap_independently(placed);
    if (!read.reader_missing) {
      INFO(read.error);
      REQUIRE(read.file);
      on_disk += (*read.file)["statistics"]["message_count"].get<std::uint64_t>();
    } else {
      on_disk += finish_interrupted_mcap(placed.string()).messages;
    }
  }
  // The second file, finished at the end.
  recorder.close();
  rig.finisher->drain();
  CHECK(rig.files(".mcap.part").size() == (ending == Ending::kChunkFailsStaysFull ? 1 : 0));
  for (const fs::path& file : rig.files(".mcap")) {
    if (file != placed) on_disk += finish_interrupted_mcap(file.string()).messages;
  }
  CHECK(recorder.messages_written() >= written);
  CHECK(on_disk == recorder.messages_written());  // counted as written: exactly what is there
  CHECK(rig.accounted() == rig.sent);
}

TEST_CASE("the next MCAP file lost while the one before still closes: no wait for the stalled disk",
          "[mcap][outputs][threads]") {
  // The daemon's pool (3 buffers: the first file's chunks take them all, and the next file's
  // messages are left out), and a larger one, where the next file's chunks are in flight,
  // queued behind the held write, when it is lost: they are let go, not waited for.
  const std::size_t buffers = GENERATE(3, 8);
  INFO(buffers << " chunk buffers");
  const io::ScopedFileSyscalls seam(watching_calls());
  RecorderRig rig("mcap-next-lost", buffers);
  McapRecorder& recorder = *rig.recorder;
  const fs::path first = rig.hold_first_write();
  while (buffers == 3 && rig.sent < 1000)
    rig.send_batch();  // the daemon's pool: every buffer taken
  recorder.rotate();
  const std::uint64_t not_written_before = recorder.messages_not_written();
  rig.send_batch();  // the next file opens
  fs::path second;
  for (const fs::path& part : rig.files(".mcap.part"))
    if (part != first) second = part;
  REQUIRE_FALSE(second.empty());
  // The next file removed while the first is still held: it is let go (its messages lost) at
  // the next flush, which must not wait for the first file's chunks.
  fs::remove(second);
  rig.send_batch();
  {
    std::lock_guard lock(mcap_writes.mutex);
    CHECK(mcap_writes.held == 1);
    CHECK_FALSE(mcap_writes.timed_out);
  }
  // With room in the pool, the next file's chunks were in flight: counted as not written.
  if (buffers == 8) CHECK(recorder.messages_not_written() > not_written_before);
  rig.release_and_settle();
  CHECK(rig.accounted() == rig.sent);
  CHECK_FALSE(fs::exists(first));  // finished and in place
  recorder.close();
  rig.finisher->drain();
  CHECK(rig.files(".mcap.part").empty());
  std::uint64_t on_disk = 0;
  for (const fs::path& file : rig.files(".mcap")) {
    const auto read = test::read_mcap_independently(file);
    if (read.reader_missing) return;
    INFO(file.string() << ": " << read.error);
    REQUIRE(read.file);
    on_disk += (*read.file)["statistics"]["message_count"].get<std::uint64_t>();
  }
  // What the lost file held is written and lost; everything else written is in the files.
  CHECK(on_disk + recorder.messages_lost() == recorder.messages_written());
  CHECK(rig.accounted() == rig.sent);
}

namespace {

// This process's descriptors open on a file named `name` (removed files included).
int descriptors_to(const std::string& name) {
  int n = 0;
  for (const auto& entry : fs::directory_iterator("/proc/self/fd")) {
    std::error_code error;
    const fs::path target = fs::read_symlink(entry.path(), error);
    if (!error && target.filename().string().rfind(name, 0) == 0) ++n;
  }
  return n;
}

// The .part that is not `but`, or none.
fs::path other_part(const RecorderRig& rig, const std::vector<fs::path>& but) {
  for (const fs::path& part : rig.files(".mcap.part"))
    if (std::find(but.begin(), but.end(), part) == but.end()) return part;
  return {};
}

}  // namespace

TEST_CASE("files lost one after another while the one before still closes: none waits",
          "[mcap][outputs][threads]") {
  // The hostile tester's case: a second file lost while the first lost one still waits for its
  // chunks (queued behind the closing file's held write) is let go too, not waited for.
  const io::ScopedFileSyscalls seam(watching_calls());
  RecorderRig rig("mcap-lost-twice", 8);
  McapRecorder& recorder = *rig.recorder;
  const fs::path first = rig.hold_first_write();
  recorder.rotate();
  std::vector<fs::path> lost;
  for (int file = 0; file < 2; ++file) {
    rig.send_batch();  // the next file opens, its chunks in flight behind the held write
    const fs::path next = other_part(rig, {first});
    REQUIRE_FALSE(next.empty());
    fs::remove(next);
    rig.send_batch();  // let go at its flush
    lost.push_back(next);
    INFO("file " << file << ": " << next);
    CHECK(descriptors_to(next.filename().string()) == 1);  // kept until its chunks are back
    std::lock_guard lock(mcap_writes.mutex);
    CHECK(mcap_writes.held == 1);  // a flush that waited would still be in the seam
    CHECK_FALSE(mcap_writes.timed_out);
  }
  rig.release_and_settle();
  CHECK(rig.accounted() == rig.sent);
  for (const fs::path& file : lost)
    CHECK(descriptors_to(file.filename().string()) == 0);
  recorder.close();
  rig.finisher->drain();
  std::uint64_t on_disk = 0;
  for (const fs::path& file : rig.files(".mcap"))
    on_disk += finish_interrupted_mcap(file.string()).messages;
  CHECK(on_disk + recorder.messages_lost() == recorder.messages_written());
}

TEST_CASE("a file lost with its own write held: the drain at exit waits for it and closes it",
          "[mcap][outputs][threads]") {
  // The writer drains the recorder before its final record: a lost file's chunks still in
  // flight are taken back there, and its descriptor closed, not left to the destructor.
  const io::ScopedFileSyscalls seam(watching_calls());
  RecorderRig rig("mcap-lost-own-held", 8);
  McapRecorder& recorder = *rig.recorder;
  const fs::path first = rig.hold_first_write();
  fs::remove(first);
  recorder.flush();  // let go: its own write is the one held
  CHECK(descriptors_to(first.filename().string()) == 1);
  release_writes();
  recorder.drain();
  CHECK(descriptors_to(first.filename().string()) == 0);
  {
    std::lock_guard lock(mcap_writes.mutex);
    CHECK_FALSE(mcap_writes.timed_out);
    mcap_writes.inode = 0;
  }
  CHECK(rig.accounted() == rig.sent);
  CHECK(recorder.messages_written() == recorder.messages_lost());
}
