// How far the upload is behind (health storage.upload, docs/deploy.md): the finished files still
// in the upload directories, their bytes and the age of the oldest; and the files the free-space
// floor or retention removed before they were uploaded.
//
// Recordings leave the vehicle through systemd/pandarcap-upload@.service (rclone move: a file is
// deleted here only once it has arrived whole). The daemon does not upload; it watches what is
// waiting. The directories are raw/ and mcap/, and frames/ with output.upload_frames; the files
// counted are exactly those the unit moves (upload_file_is_ours: finished files of ours and the
// recordings' sidecars; never NAME.part, a hidden file, or another program's file), in each
// directory alike.
//
// Counted off the writer's hot path and without holding it up: step() is called once a second
// (the health tick) and reads the directories for at most kStepBudgetNs (getdents64 into a buffer
// of its own, one fstatat per file of ours), going on from where it stopped at the next call; a
// pass that ends publishes its figures, and the next pass begins at the next call. raw/ and mcap/
// (hourly recordings) take well under a millisecond; frames/ with hundreds of thousands of files
// takes a pass of a few minutes, which the figures then lag by. A file removed by the floor or
// retention leaves the published figures at once (removed()). Nothing is allocated after
// prepare(). Owned by the writer thread.
//
// "Before it was uploaded": a file of ours is still in an upload directory only until the upload
// has moved it, so with output.upload every such file the floor or retention removes had not
// arrived: counted (files, bytes) and named in the health's reason. Without output.upload nothing
// is expected to leave, and nothing is counted.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string_view>
#include <vector>

#include "core/health/health.hpp"
#include "daemon/output/directory_reader.hpp"
#include "daemon/output/output_names.hpp"

namespace pandarcap {

class UploadBacklog {
 public:
  static constexpr std::int64_t kStepBudgetNs = 4'000'000;  // the directory reading per step

  explicit UploadBacklog(bool enabled);

  // At start-up: an upload directory.
  void watch(const std::filesystem::path& directory);
  // At start-up, once the directories are watched: a whole pass, so the first health record has
  // the figures.
  void prepare();

  // Once a second: reads on for at most `budget_ns`, a pass's figures published when it ends.
  void step(std::int64_t budget_ns = kStepBudgetNs) noexcept;

  enum class Remover : std::uint8_t { kFloor, kRetention };
  // A file (its path, its bytes) the floor or retention just removed. Counted as removed before
  // upload when upload is on and it is one that leaves by upload (in a watched directory).
  void removed(std::string_view path, std::uint64_t bytes, Remover by) noexcept;

  // The figures into the health record's gauges, their age as of `now_realtime_ns` (the clock
  // the files' modification times are on).
  void fill(std::int64_t now_realtime_ns, UploadGauges& gauges) const noexcept;
  std::uint64_t files_removed_before_upload() const noexcept { return files_removed_; }
  std::uint64_t bytes_removed_before_upload() const noexcept { return bytes_removed_; }

 private:
  struct Figures {
    std::uint64_t bytes = 0, files = 0;
    std::int64_t oldest_mtime_ns = 0;  // meaningful when files > 0
  };

  bool enabled_;
  std::vector<std::filesystem::path> directories_;
  std::vector<char> dirent_buffer_;  // allocated with the object (start-up)
  DirectoryReader reader_;
  std::size_t directory_ = 0;  // the pass's current directory
  bool in_pass_ = false;
  Figures counting_;   // the pass under way
  Figures published_;  // the last pass's, less what was removed since
  bool known_ = false;
  std::uint64_t files_removed_ = 0, bytes_removed_ = 0;
  char last_removed_[sizeof(UploadGauges::last_removed)] = {};
  bool last_removed_by_floor_ = false;
};

}  // namespace pandarcap
