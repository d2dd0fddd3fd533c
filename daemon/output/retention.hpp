// Retention of one kind of output file (frames, recordings): at most max_files files and
// max_bytes bytes, the oldest removed first. 0 means no limit; with neither limit set no list is
// kept at all (it would only grow).
//
// The list holds every file of ours, those of earlier runs included (adopted at start-up, oldest
// first), so restarts and crash loops cannot fill the disk. Adding a file costs one allocation
// (its name), which is why nothing is listed without a limit: the name is copied only then. Owned
// by the writer thread.
#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>
#include <filesystem>
#include <string_view>
#include <utility>

namespace pandarcap {

class Retention {
 public:
  Retention(std::uint64_t max_files, std::uint64_t max_bytes) noexcept
      : max_files_(max_files), max_bytes_(max_bytes) {}

  bool limited() const noexcept { return max_files_ != 0 || max_bytes_ != 0; }
  // Files listed (kept); the newest are the last added.
  std::size_t size() const noexcept { return files_.size(); }

  // A file just finished (the newest): listed, then the oldest removed while over a limit.
  void add(std::string_view path, std::uint64_t bytes) {
    if (!limited()) return;
    files_.emplace_back(path, bytes);
    enforce();
  }
  // A file found at start-up, listed without enforcing yet: earlier runs' files are adopted
  // oldest first, then enforce() applies the limits once.
  void adopt(std::string_view path, std::uint64_t bytes) {
    if (limited()) files_.emplace_back(path, bytes);
  }
  // Removes the oldest files while over a limit (a removal that fails is not retried); returns
  // how many left the list.
  std::size_t enforce();

 private:
  std::uint64_t max_files_, max_bytes_;
  std::deque<std::pair<std::filesystem::path, std::uint64_t>> files_;  // oldest first
};

}  // namespace pandarcap
