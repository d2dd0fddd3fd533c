// A file system of the test's own on a loop device (an image file in a scratch directory), which
// the test can fail the ways a vehicle's disk fails: shut down as a power cut leaves it
// (FS_IOC_SHUTDOWN with no flush of data or journal, as xfstests' godown), forced read-only by an
// error (ext4's errors=remount-ro), or a btrfs subvolume set read-only and back.
//
// Root only (mount, loop devices). Where the machine cannot (no root, no loop device, no
// mkfs for the type), available() is false: the test WARNs and returns, except under CI=true,
// where CI runs as root on a machine that can and a test that cannot run must fail.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>

namespace pandarcap::test {

class LoopFileSystem {
 public:
  // Makes a `bytes` image of `type` ("ext4", "btrfs") at `image` and mounts it at `mount_point`
  // with `options` (e.g. "errors=remount-ro").
  LoopFileSystem(const std::filesystem::path& image, const std::filesystem::path& mount_point,
                 std::uint64_t bytes, const std::string& type = "ext4",
                 const std::string& options = "");
  ~LoopFileSystem();  // unmounted, the image removed
  LoopFileSystem(const LoopFileSystem&) = delete;
  LoopFileSystem& operator=(const LoopFileSystem&) = delete;

  // Mounted and usable; when not, the reason was WARNed (or, under CI=true, FAILed).
  bool available() const noexcept { return mounted_; }
  const std::filesystem::path& mount_point() const noexcept { return mount_point_; }

  // A power cut, as the file system sees one: from now on nothing reaches the disk, neither data
  // nor journal (EXT4_GOING_FLAGS_NOLOGFLUSH / XFS_FSOP_GOING_FLAGS_NOLOGFLUSH); every later
  // call on it fails (EIO). Returns false when the ioctl is refused.
  bool shut_down();
  // Unmounted and mounted again: what the disk held at the cut, the journal replayed.
  bool remount();
  // ext4 only: an error as a failing disk reports one, which errors=remount-ro turns into a
  // read-only file system (EROFS for every write from then on). Returns false if not possible.
  bool force_read_only();

 private:
  std::filesystem::path image_, mount_point_;
  std::string type_, options_;
  std::string device_;  // /dev/loopN while mounted
  bool mounted_ = false;
};

// Runs `command` through /bin/sh; true when it exits 0. Its output goes to the test's log.
bool shell(const std::string& command);

}  // namespace pandarcap::test
