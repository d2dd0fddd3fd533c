// Retention of one kind of output file (frames, recordings): at most max_files files and
// max_bytes bytes, the oldest removed first. 0 means no limit; with neither limit set no list is
// kept at all (it would only grow). A recording goes with its sidecars (STEM.calibration.csv,
// STEM.sensor.json; output_names.hpp), and each removal is told to the owner (on_removed(): the
// upload backlog counts a file that had not been uploaded).
//
// The list holds every file of ours, those of earlier runs included (adopted at start-up, oldest
// first), so restarts and crash loops cannot fill the disk. The names are copied into slots that
// keep their memory (file_list.hpp): at steady state, a file in and a file out, nothing is
// allocated; nothing is listed without a limit (the list would only grow). Owned by the writer
// thread.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <string_view>
#include <utility>

#include "daemon/output/file_list.hpp"

namespace pandarcap {

// Removes the sidecars of the recording at `recording_path` (a .pcap or .pcap.zst of ours; any
// other name has none), those that are there. Allocates nothing.
void remove_sidecars(std::string_view recording_path) noexcept;

class Retention {
 public:
  Retention(std::uint64_t max_files, std::uint64_t max_bytes) noexcept
      : max_files_(max_files), max_bytes_(max_bytes) {}

  bool limited() const noexcept { return max_files_ != 0 || max_bytes_ != 0; }
  // At start-up: the list's slots made for the files it will hold at steady state (max_files
  // and the one added before the oldest goes; 64 with a byte limit only; at most 1024), with
  // room for paths of `path_bytes`, so that the first file after the warm-up allocates nothing.
  void reserve(std::size_t path_bytes) {
    if (!limited()) return;
    const std::uint64_t slots =
        max_files_ != 0 ? std::min<std::uint64_t>(max_files_ + 1, 1024) : 64;
    files_.reserve(static_cast<std::size_t>(slots), path_bytes);
  }
  // Files listed (kept); the newest are the last added.
  std::size_t size() const noexcept { return files_.size(); }

  // A file just finished (the newest): listed, then the oldest removed while over a limit.
  void add(std::string_view path, std::uint64_t bytes) {
    if (!limited()) return;
    files_.push_back(path, bytes);
    bytes_ += bytes;
    enforce();
  }
  // A file found at start-up, listed without enforcing yet: earlier runs' files are adopted
  // oldest first, then enforce() applies the limits once.
  void adopt(std::string_view path, std::uint64_t bytes) {
    if (!limited()) return;
    files_.push_back(path, bytes);
    bytes_ += bytes;
  }
  // Removes the oldest files while over a limit (a removal that fails is not retried); returns
  // how many left the list. Allocates nothing (the callback aside).
  std::size_t enforce();
  // A listed file removed by the free-space floor (space_floor.hpp): off the list, its bytes no
  // longer counted. Searched from the oldest (the floor removes the oldest). Allocates nothing.
  void forget(std::string_view path) noexcept;
  // Called with each file enforce() removed (its path, its bytes), its sidecars gone with it.
  void on_removed(std::function<void(std::string_view, std::uint64_t)> callback) {
    on_removed_ = std::move(callback);
  }

 private:
  std::uint64_t max_files_, max_bytes_;
  FileList files_;           // oldest first, each with its bytes
  std::uint64_t bytes_ = 0;  // theirs, all together
  std::function<void(std::string_view, std::uint64_t)> on_removed_;
};

// A recorder's finished files of this run still kept, each with what it holds (packets,
// messages), so that the end can count what vanished from disk with its file
// (pcap_packets_lost, mcap_messages_lost). Retention removes the oldest first, so they leave the
// front. At steady state nothing is allocated (file_list.hpp). Owned by the writer thread.
// The files a RecordedFiles list has room for from the start: 256 recordings, some 30 hours at
// the default rotation (1 GiB) of one sensor.
inline constexpr std::size_t kRecordedFilesReserved = 256;

class RecordedFiles {
 public:
  // A file just finished and put in place; then the list trimmed to what `retention` keeps.
  void add(std::string_view path, std::uint64_t items, const Retention& retention);
  // At start-up: room for the first `files` files (paths up to `path_bytes`) made now. Without
  // a retention limit the list grows with the run: past these, one allocation per file.
  void reserve(std::size_t files, std::size_t path_bytes) { files_.reserve(files, path_bytes); }

  struct Gone {
    std::size_t files = 0;
    std::uint64_t items = 0;
  };
  // The listed files that are no longer on disk (removed while the run went on), and what they
  // held; the list is emptied. A file that cannot be asked about counts as there.
  Gone take_gone();
  // A listed file removed on purpose by the free-space floor (space_floor.hpp): off the list, so
  // take_gone() does not count it as lost (as retention's removals are not). Allocates nothing.
  void forget(std::string_view path) noexcept;

 private:
  FileList files_;  // oldest first, each with what it holds
};

}  // namespace pandarcap
