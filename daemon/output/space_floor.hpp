// The floor of free space (output.min_free_bytes, output.min_free_percent; docs/storage.md), and
// the free space the health record reports (storage.free_bytes, hours_left).
//
// The output directories (frames/, raw/, mcap/, and the health directory for the free space
// only) are grouped by file system at start-up (prepare()). Once a second (tend(), from the
// writer thread) each file system is asked its free space: one statvfs each, nothing else while
// above the floor. The floor is the larger of min_free_bytes and min_free_percent of the file
// system's size, and never less than the room the outputs' writes stop short of
// (kOutputFloorBytes, health_room.hpp) plus 2 s of writing at the measured rate (write_rate()):
// a floor below that could not act before the writes were refused (a floor of 12 MB on a small
// disk gave write errors with our old files still there). That minimum only rises: with the
// rate, logged when it does. Below the floor, the output directories on that file system are
// read (a directory scan) and the oldest of our files there are removed, oldest first across
// frames, recordings and MCAP alike, until the floor is back:
//   - ours: frames/frame_<N>_<UTC>[...].pcd, raw/pandarcap_<UTC>_<N>[...].pcap and .pcap.zst,
//     mcap/pandarcap_<UTC>_<N>[...].mcap, as regular files (a link never), earlier runs'
//     included (output_names.hpp). A recording goes with its sidecars (STEM.calibration.csv,
//     STEM.sensor.json). Never anything else: not the open recording (.part), not a temporary
//     (.NAME.tmp), not calibration.csv or sensor.json, not another program's file.
//   - oldest: by modification time (when the file was finished), then by name.
// The oldest files found by a scan are kept for the next removals: the disk is read again only
// when they are used up (or gone: uploaded, removed by someone else), not every second.
// Between two seconds, a write the space guard would refuse asks the floor first (make_room()),
// which removes the oldest of ours until the write and the guard's room fit: whatever the
// floor, no write is refused while a file of ours is left to remove.
// Each removal is counted (files_removed(), bytes_removed()) and reported to the owner (the
// recorders then neither count the file as lost at the end nor keep it on their retention
// lists; the upload backlog counts it when it had not been uploaded); the removals are logged at
// most every 10 s, summed. When no file of ours is left to remove and the file system is still
// below the floor (someone else fills it), that is logged (at most every 10 s) and the full-disk
// behaviour applies (health_room.hpp): writes stop short of the health files' room, counted.
//
// Nothing is allocated after prepare(): the scan reads directories with getdents64 into a buffer
// of its own, keeps the oldest kCandidates files of a pass in a preallocated heap, and removes
// them with unlink; a file system still below the floor after a pass is scanned again (a few
// passes a second at most). Owned by the writer thread.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "daemon/output/health_room.hpp"
#include "daemon/output/output_names.hpp"

namespace pandarcap {

// The least floor held whatever is configured: `reserve_bytes` (the room the outputs' writes
// stop short of) plus 2 s of writing at `bytes_per_second`.
std::uint64_t minimum_floor_bytes(std::uint64_t reserve_bytes, double bytes_per_second) noexcept;

class SpaceFloor {
 public:
  static constexpr std::size_t kCandidates = 256;  // the oldest files kept per pass

  // `min_free_bytes` and `min_free_percent` (of the file system's size): the floor is the larger,
  // raised to minimum_floor_bytes(reserve_bytes, rate) (the daemon's reserve is
  // kOutputFloorBytes; all three 0: no floor at all, the free space is still asked, for the
  // health record).
  SpaceFloor(std::uint64_t min_free_bytes, double min_free_percent,
             std::uint64_t reserve_bytes = kOutputFloorBytes);

  // At start-up: an output directory (`kind` kNone: only its free space is reported); returns
  // its handle, for free_bytes().
  int watch(const std::filesystem::path& directory, FloorKind kind);
  // At start-up, once the directories exist: grouped by file system, the buffers allocated.
  void prepare();
  // Called with each file the floor removed (its path, and its directory's kind), before the
  // count goes up: the recorders forget it. Set at start-up.
  // With the file's bytes. Its sidecars go with a recording, without a call of their own.
  void on_removed(std::function<void(FloorKind, std::string_view, std::uint64_t)> callback) {
    on_removed_ = std::move(callback);
  }

  // For the tests: the free space asked of `query` instead of statvfs (a fake disk).
  using SpaceQuery = std::function<std::optional<FileSystemSpace>(const std::filesystem::path&)>;
  void ask_space_with(SpaceQuery query) { query_ = std::move(query); }

  // Once a second, before tend(): the outputs' bytes written per second (the last minute's).
  // The floor's minimum follows it up, never down; a rise is logged (at most every 10 s).
  void write_rate(double bytes_per_second, std::int64_t now_ns) noexcept;
  // Once a second: the free space asked, and the floor held. `now_ns` is monotonic.
  void tend(std::int64_t now_ns) noexcept;
  // A write of `bytes` under `directory` (a watched one) that the space guard would refuse:
  // the oldest of ours on its file system removed until the write fits above the reserve with
  // the floor's 2 s of writing to spare. True when something was removed (ask again).
  bool make_room(std::string_view directory, std::uint64_t bytes, std::int64_t now_ns) noexcept;
  // The floor held on `handle`'s file system now (its size as last asked); 0 when not known.
  std::uint64_t floor_bytes(int handle) const noexcept;
  // The minimum it is never below now (minimum_floor_bytes at the highest rate seen).
  std::uint64_t minimum_bytes() const noexcept { return minimum_; }

  // The free space on `handle`'s file system at the last tend(); nothing when not known.
  std::optional<std::uint64_t> free_bytes(int handle) const noexcept;
  // Which file system `handle` is on (handles with the same number share one).
  int file_system(int handle) const noexcept;
  std::uint64_t files_removed() const noexcept { return files_removed_; }
  std::uint64_t bytes_removed() const noexcept { return bytes_removed_; }
  bool enabled() const noexcept {
    return min_free_bytes_ != 0 || min_free_percent_ > 0 || reserve_bytes_ != 0;
  }

 private:
  struct Directory {
    std::filesystem::path path;
    FloorKind kind;
    int volume = -1;
  };
  struct Volume {
    std::size_t first_directory = 0;  // its free space is asked there
    bool known = false;
    FileSystemSpace space;
    // Since the last log line: what was removed, and whether the floor could not be held.
    std::uint64_t files_unlogged = 0, bytes_unlogged = 0;
    std::int64_t last_log_ns = -1, last_unheld_log_ns = -1;
  };
  struct Candidate {
    std::int64_t mtime_ns;
    std::uint64_t bytes, blocks_bytes;
    std::uint32_t directory;
    char name[256];
  };

  std::uint64_t configured_floor(const FileSystemSpace& space) const noexcept;
  std::uint64_t floor_of(const FileSystemSpace& space) const noexcept;  // raised to minimum_
  std::optional<FileSystemSpace> ask(const std::filesystem::path& at) const noexcept;
  // Removes the oldest of ours on volume `v` until its free space is at `floor` (a few passes at
  // most); false when none of ours was left to remove.
  bool hold(int v, std::uint64_t floor) noexcept;
  // One pass over `volume`'s directories: the oldest files of ours, oldest first, in candidates_
  // (candidate_count_ of them; next_candidate_ the first not yet removed).
  void scan(int volume) noexcept;
  // Removes the oldest candidates until `volume` is back at its floor; returns how many.
  std::size_t remove_oldest(int volume, std::uint64_t floor) noexcept;
  void log(Volume& volume, std::uint64_t floor, std::int64_t now_ns, bool force) noexcept;
  // Where the minimum is above the configured floor: said (at the start, then as it rises).
  void log_minimum(std::int64_t now_ns) noexcept;

  std::uint64_t min_free_bytes_;
  double min_free_percent_;
  std::uint64_t reserve_bytes_;
  std::uint64_t minimum_;             // minimum_floor_bytes at the highest rate seen
  std::uint64_t minimum_logged_ = 0;  // the minimum the log last gave
  std::int64_t last_minimum_log_ns_ = -1;
  double rate_ = 0;      // the write rate minimum_ was raised for
  bool tended_ = false;  // tend() has run (the start's log line is said)
  std::vector<Directory> directories_;
  std::vector<Volume> volumes_;
  std::vector<Candidate> candidates_;  // a max-heap by age while scanning, then sorted
  std::size_t candidate_count_ = 0, next_candidate_ = 0;
  int candidate_volume_ = -1;  // the volume candidates_ were scanned from
  std::vector<char> dirent_buffer_;
  std::string removed_path_;  // the path handed to on_removed_ (its capacity reserved)
  std::function<void(FloorKind, std::string_view, std::uint64_t)> on_removed_;
  SpaceQuery query_;  // empty: statvfs
  std::uint64_t files_removed_ = 0, bytes_removed_ = 0;
};

}  // namespace pandarcap
