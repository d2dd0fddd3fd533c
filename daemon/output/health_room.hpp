// Keeps the health files writable whatever fills their file system (docs/reliability.md, "Health
// that never freezes").
//
// Two mechanisms, one for each way a disk fills:
//   - The daemon's own outputs stop short: frames, recordings and MCAP are not written while
//     their file system has less than kOutputFloorBytes free (allows(), checked before each
//     write; a refused write is counted and said in the health like a failed one). Their disk
//     never fills to the last block, and the health files keep the room they need. Before it
//     refuses, the free-space floor is asked to make room (make_room_with(): it removes the
//     oldest of our files), so a write is refused only when none of ours is left.
//   - Someone else fills the disk: a reserve file in the health directory,
//     HEALTH_DIR/.pandarcap-health-reserve, holds kHealthReserveBytes allocated at start-up.
//     When a health write fails for want of space (ENOSPC, EDQUOT), a piece of it is given back
//     (release_piece()) and the write tried again; tend() (every second) grows it back where
//     space allows, and makes it again if its directory went away. At a clean end it is removed.
//     8 MiB is some 40 minutes of health.jsonl lines with the disk full to the last block.
// Owned by the writer thread; nothing is allocated after prepare().
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace pandarcap {

inline constexpr std::uint64_t kOutputFloorBytes = 32ull << 20;
inline constexpr std::uint64_t kHealthReserveBytes = 8ull << 20;
inline constexpr std::uint64_t kHealthReservePieceBytes = 256ull << 10;

// Free space on the file system holding `path`, or its nearest existing parent (a removed
// directory is made again on the same file system): what an unprivileged writer may use
// (statvfs f_bavail), and the file system's size. Nothing when it cannot be asked. The usual case
// (the path exists) asks once and allocates nothing.
struct FileSystemSpace {
  std::uint64_t free = 0, size = 0;
};
std::optional<FileSystemSpace> file_system_space_at(const std::filesystem::path& path) noexcept;
inline std::optional<std::uint64_t> free_bytes_at(const std::filesystem::path& path) noexcept {
  const auto space = file_system_space_at(path);
  return space ? std::optional<std::uint64_t>(space->free) : std::nullopt;
}

class HealthRoom {
 public:
  // Watches the file systems of the output directories given to watch() and keeps the reserve
  // in `health_dir` (none when empty: no health files are written).
  explicit HealthRoom(std::filesystem::path health_dir);
  ~HealthRoom();
  HealthRoom(const HealthRoom&) = delete;
  HealthRoom& operator=(const HealthRoom&) = delete;

  // An output directory whose writes allows() will judge; returns its handle. At start-up.
  int watch(const std::filesystem::path& directory);
  // Creates (or takes over, from a killed run) the reserve at its full size. Throws
  // std::system_error when the reserve cannot even be created; one that cannot be sized (a
  // file-size limit) is warned about and tried again every second (tend()).
  void prepare();

  // Whether `bytes` may be written under the watched directory `handle` now: its file system
  // keeps kOutputFloorBytes free after them. Asks the file system at most every 100 ms and counts
  // what was allowed since. When not, `reason` says why ("12 MiB free on /data, 32 MiB kept for
  // health").
  bool allows(int handle, std::uint64_t bytes, std::string& reason) noexcept;
  // Asked before allows() refuses: room for `bytes` under the watched `directory`, made by
  // removing files (the free-space floor's oldest); the space is then asked again. Set at
  // start-up; called on the writer thread.
  using MakeRoom = std::function<bool(std::string_view directory, std::uint64_t bytes)>;
  void make_room_with(MakeRoom make_room) { make_room_ = std::move(make_room); }

  // A health write failed for want of space: a piece of the reserve is given back. False when
  // none is left (the write then fails, counted).
  bool release_piece() noexcept;
  // Once a second: the reserve grown back towards its size where its file system allows (keeping
  // the floor), and made again when it was removed with its directory.
  void tend() noexcept;
  // At a clean end, after the last health record: the reserve is not needed any more.
  void remove() noexcept;

  std::uint64_t reserve_bytes() const noexcept { return reserve_size_; }

 private:
  struct Volume {
    std::filesystem::path directory;
    std::int64_t checked_ns = -1;  // when its free space was last asked
    std::uint64_t free = 0;        // then, less what was allowed since
    bool known = false;
  };
  void open_reserve();
  bool resize_reserve(std::uint64_t size) noexcept;

  std::filesystem::path health_dir_;
  std::string reserve_path_;
  int reserve_fd_ = -1;
  std::uint64_t reserve_size_ = 0;
  std::vector<Volume> volumes_;
  MakeRoom make_room_;
};

}  // namespace pandarcap
