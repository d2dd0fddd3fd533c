// The syncs that make the writer's files durable, on a thread of their own, so the writer's loop
// never waits for the disk to confirm what it wrote.
//
//   writer thread                                  finisher thread ("pc-finish")
//   take(): a free job, filled in
//   submit(job)  ------ to_finish (SpscQueue) ----->  kPlace:   the file's data synced, then
//                                                               renamed without replacing (a taken
//                                                               name becomes "_dupN"), then its
//                                                               directory synced
//                                                     kReplace: data synced, renamed over `to`
//                                                               (health's .prom, each second)
//                                                     kSync:    data synced (a recording still
//                                                               being written, health.jsonl), and
//                                                               its directory the first time
//   collect()    <------ done (SpscQueue) ---------   the result, in the job
//   the owner counts it (FinishReceiver)
//
// Every synced file but the health's then leaves the page cache (AfterSync::kDropCached): a
// recording is written once and read again rarely, and on a virtual machine that backs guest memory
// lazily, the fresh pages an ever-growing cache takes cost the writer more than its copy into them
// (docs/performance.md, "Seventh round").
//
// Why: a power cut must not leave a file under its final name with less in it than it was
// written with (docs/reliability.md, "Power cut"). The kernel writes a rename to the journal on
// its own schedule and a file's data on another (ext4's delayed allocation, seconds later), so a
// finished file's data is synced before its rename and its directory after; a recording in
// progress every output.sync_interval_seconds, so a cut loses at most that much of it (the next
// start finishes its .part). fdatasync waits for the disk (milliseconds on an SSD, far more on a
// busy SD card): here, not in the writer's loop.
//
// Order: jobs are done one at a time, in the order submitted, so sidecars submitted before their
// recording are in place before it. Directory syncs are batched: the jobs found queued together
// share one fsync per directory, and none is reported done before its directory is synced.
//
// A job is filled by the writer, owned by the finisher from submit() until it is handed back, and
// by the writer again from collect(); the queues' acquire and release make each side's writes
// visible to the other. Every job (its names reserved for a path's length) is allocated at
// construction: taking, submitting and collecting allocate nothing (a name longer than
// kReservedPath allocates once, a "_dupN" name on the finisher thread). With every job in flight,
// take() waits for one to come back, collecting meanwhile: a disk slower than the outputs then
// slows the writer, as a slow write(2) does, and frames are dropped (counted) upstream.
//
// The thread starts with every signal blocked (the supervisor takes them with sigwait) and stops
// in the destructor, after finishing every job still queued.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "ringbuf/spsc_queue.hpp"

namespace pandarcap {

// Whose file a job is: the part of the writer that counts its result.
enum class FinishOwner : std::uint8_t { kFrames, kRecordings, kSidecars, kMcap, kHealth };

struct FinishJob {
  enum class Kind : std::uint8_t { kPlace, kReplace, kSync };
  Kind kind = Kind::kSync;
  FinishOwner owner = FinishOwner::kFrames;
  // kPlace / kReplace: the temporary name written; kSync: the file to sync.
  std::string from;
  // kPlace: the final name asked for, and after the job the name used; kReplace: the name the
  // file replaces. Empty for kSync.
  std::string to;
  // kSync: its directory is synced too (a file just created: its name must survive as well).
  bool sync_directory = false;
  // A kPlace or kReplace job that fails before its rename removes `from` (a frame's temporary
  // file); otherwise it is left for the next start to finish (a recording's .part).
  bool remove_on_failure = false;
  // The owner's, handed back as given.
  std::uint64_t bytes = 0, items = 0;
  std::int64_t stamp_ns = 0;

  // The result, set by the finisher.
  bool placed = false;                // kPlace / kReplace: renamed (the file has its final name)
  bool name_taken = false;            // kPlace: the name asked for existed; `to` is the one used
  std::int64_t done_realtime_ns = 0;  // when it was done (CLOCK_REALTIME): a frame's latency
  bool failed = false;                // a sync or rename failed: `error` says which and why
  int error_code = 0;                 // its errno
  std::array<char, 256> error{};

  std::string_view error_text() const noexcept { return error.data(); }
};

// The writer's side of a finished job: counts it, keeps its name (retention), logs a failure.
class FinishReceiver {
 public:
  virtual void finished(const FinishJob& job) = 0;

 protected:
  ~FinishReceiver() = default;
};

class FileFinisher {
 public:
  // Room for a path this long in every job's names, reserved up front.
  static constexpr std::size_t kReservedPath = 4096;
  // The writer's: over a second of frames at ten sensors' rate (100 frames a second), so a disk
  // that takes a few hundred milliseconds for one journal commit does not stop the writer.
  static constexpr std::size_t kDefaultJobs = 128;

  // `jobs` in flight at most; finished jobs go to `receiver` (from collect(), take(), drain()).
  explicit FileFinisher(FinishReceiver& receiver, std::size_t jobs = kDefaultJobs);
  ~FileFinisher();
  FileFinisher(const FileFinisher&) = delete;
  FileFinisher& operator=(const FileFinisher&) = delete;

  // ---- The writer thread ---------------------------------------------------------------------
  // A free job, its fields reset (names cleared, capacity kept). Waits, collecting, while every
  // job is in flight.
  FinishJob& take() noexcept;
  void submit(FinishJob& job) noexcept;
  // The two jobs the writer's parts hand over, taken and submitted in one call:
  // `from` synced and put in place as `to` (kPlace), with what its owner wants back;
  struct Placing {
    std::uint64_t bytes = 0, items = 0;
    std::int64_t stamp_ns = 0;
    bool remove_on_failure = false;
  };
  void place(FinishOwner owner, std::string_view from, std::string_view to,
             const Placing& placing) noexcept;
  // `path` synced where it is (kSync), its directory too unless `directory_synced` (then set).
  void sync(FinishOwner owner, std::string_view path, bool& directory_synced) noexcept;
  // Hands each finished job to the receiver; returns how many. Never waits.
  std::size_t collect() noexcept;
  // Waits until every submitted job is finished and collected (the end of a run, a test).
  void drain() noexcept;
  std::size_t in_flight() const noexcept { return in_flight_; }

 private:
  void run() noexcept;
  // A job of the batch: its writeback started.
  void start(FinishJob& job) noexcept;
  // Its data synced, then renamed; its directory is noted for the batch's sync.
  void process(FinishJob& job) noexcept;
  // The batch's directories synced, then its jobs handed back.
  void end_batch() noexcept;

  FinishReceiver& receiver_;
  ringbuf::SpscQueue<FinishJob*> to_finish_, done_;
  std::vector<std::unique_ptr<FinishJob>> jobs_;
  std::vector<FinishJob*> free_;  // the writer's
  std::size_t in_flight_ = 0;     // the writer's
  // The finisher thread's: the jobs of the batch in progress and the directories they renamed in.
  static constexpr std::size_t kMaxBatch = 64;
  std::vector<FinishJob*> batch_;
  std::vector<std::string> batch_directories_;
  std::size_t batch_directory_count_ = 0;
  std::string directory_;  // scratch
  std::thread thread_;
};

}  // namespace pandarcap
