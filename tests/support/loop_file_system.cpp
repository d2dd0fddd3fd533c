#include "support/loop_file_system.hpp"

#include <fcntl.h>
#include <sys/ioctl.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <chrono>
#include <cstdlib>
#include <fstream>
#include <string_view>

#include "bench/child_process.hpp"
#include "support/test_support.hpp"

using namespace std::chrono_literals;

namespace pandarcap::test {
namespace {

// <linux/fs.h> does not carry them: xfs_fs.h and ext4's own header do, with the same values.
constexpr unsigned long kFsIocShutdown = 0x8004587D;  // _IOR('X', 125, __u32)
constexpr std::uint32_t kGoingDownNoLogFlush = 2;

bool under_ci() {
  const char* ci = std::getenv("CI");
  return ci != nullptr && std::string_view(ci) == "true";
}

// The device a mount point is mounted from (/proc/mounts), "" if it is not one.
std::string device_of(const std::filesystem::path& mount_point) {
  std::ifstream mounts("/proc/mounts");
  std::string device, where, rest;
  std::string found;
  while (mounts >> device >> where && std::getline(mounts, rest)) {
    if (where == mount_point.string()) found = device;  // the last mount there is the top one
  }
  return found;
}

}  // namespace

bool shell(const std::string& command) {
  const CommandResult result = run_command(command + " 2>&1");
  if (result.exit_code != 0)
    UNSCOPED_INFO(command << ": exit " << result.exit_code << "\n" << result.out);
  return result.exit_code == 0;
}

LoopFileSystem::LoopFileSystem(const std::filesystem::path& image,
                               const std::filesystem::path& mount_point, std::uint64_t bytes,
                               const std::string& type, const std::string& options)
    : image_(image), mount_point_(mount_point), type_(type), options_(options) {
  std::filesystem::create_directories(mount_point_);
  std::string why;
  if (::geteuid() != 0) {
    why = "not root";
  } else if (!shell("truncate -s " + std::to_string(bytes) + " '" + image_.string() + "'") ||
             !shell("mkfs." + type_ + " -q '" + image_.string() + "'")) {
    why = "cannot make a " + type_ + " image (mkfs." + type_ + ")";
  } else if (!remount()) {
    why = "cannot mount a " + type_ + " image on a loop device";
  }
  if (why.empty()) return;
  if (under_ci()) {
    FAIL("a loop-mounted " << type_ << " file system is needed under CI=true: " << why);
  }
  WARN("a loop-mounted " << type_ << " file system is not possible here (" << why
                         << "): not tested");
}

LoopFileSystem::~LoopFileSystem() {
  if (mounted_)
    shell("umount '" + mount_point_.string() + "' || umount -l '" + mount_point_.string() + "'");
  std::error_code ignored;
  std::filesystem::remove(image_, ignored);
}

bool LoopFileSystem::shut_down() {
  const int fd = ::open(mount_point_.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return false;
  std::uint32_t flags = kGoingDownNoLogFlush;
  const bool done = ::ioctl(fd, kFsIocShutdown, &flags) == 0;
  ::close(fd);
  return done;
}

bool LoopFileSystem::remount() {
  if (mounted_) {
    mounted_ = false;
    if (!shell("umount '" + mount_point_.string() + "'")) return false;
    // The unmounted file system may outlive umount for a moment (a shut-down ext4's journal
    // being aborted): its loop device is released only then. Mounted before that, "-o loop"
    // would take the same device again, and with it the old, shut-down file system.
    const bool released = harness::wait_until(
        [&] { return run_command("losetup -j '" + image_.string() + "'").out.empty(); }, 20s);
    if (!released) {
      UNSCOPED_INFO(image_.string() << " still on a loop device 20 s after its unmount");
      return false;
    }
  }
  // "-o loop" takes a free loop device, released by itself at the unmount (autoclear; a losetup
  // -d right after the unmount can still find it busy, and a device left attached keeps a
  // deleted image's space). Under a lock: the tests run in parallel (ctest -j).
  const std::string with = options_.empty() ? "loop" : "loop," + options_;
  mounted_ = shell("flock /tmp/pandarcap-test-loop.lock mount -t " + type_ + " -o " + with + " '" +
                   image_.string() + "' '" + mount_point_.string() + "'");
  if (mounted_) device_ = device_of(mount_point_);
  return mounted_;
}

bool LoopFileSystem::force_read_only() {
  if (type_ != "ext4" || !mounted_) return false;
  // /dev/loop3 -> /sys/fs/ext4/loop3/trigger_fs_error (a debugging knob of ext4's, Linux 4.x+).
  const std::string name = std::filesystem::path(device_).filename().string();
  std::ofstream trigger("/sys/fs/ext4/" + name + "/trigger_fs_error");
  trigger << "pandarcap test: a failing disk\n";
  trigger.flush();
  return trigger.good();
}

}  // namespace pandarcap::test
