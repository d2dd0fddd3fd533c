#include "daemon/output/health_room.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <sys/stat.h>
#include <sys/statvfs.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <iterator>
#include <system_error>

#include "daemon/clocks.hpp"
#include "daemon/io/errors.hpp"

namespace pandarcap {

std::optional<FileSystemSpace> file_system_space_at(const std::filesystem::path& path) noexcept {
  struct statvfs info {};
  const auto space = [&info] {
    return FileSystemSpace{static_cast<std::uint64_t>(info.f_bavail) * info.f_frsize,
                           static_cast<std::uint64_t>(info.f_blocks) * info.f_frsize};
  };
  // The usual case asks once and allocates nothing (the writer asks every 100 ms).
  if (::statvfs(path.c_str(), &info) == 0) return space();
  try {
    std::filesystem::path at = path;
    while (errno == ENOENT && at.has_parent_path() && at.parent_path() != at) {
      at = at.parent_path();
      if (::statvfs(at.c_str(), &info) == 0) return space();
    }
  } catch (const std::exception&) {
  }
  return std::nullopt;
}

HealthRoom::HealthRoom(std::filesystem::path health_dir) : health_dir_(std::move(health_dir)) {
  if (!health_dir_.empty()) reserve_path_ = (health_dir_ / ".pandarcap-health-reserve").native();
}

HealthRoom::~HealthRoom() {
  if (reserve_fd_ >= 0) ::close(reserve_fd_);
}

int HealthRoom::watch(const std::filesystem::path& directory) {
  volumes_.push_back(Volume{directory});
  return static_cast<int>(volumes_.size() - 1);
}

void HealthRoom::open_reserve() {
  reserve_fd_ = ::open(reserve_path_.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0600);
  if (reserve_fd_ < 0) {
    io::throw_errno("cannot create", reserve_path_);
  }
  struct stat info {};
  reserve_size_ = ::fstat(reserve_fd_, &info) == 0 ? static_cast<std::uint64_t>(info.st_size) : 0;
}

void HealthRoom::prepare() {
  if (reserve_path_.empty()) return;
  std::filesystem::create_directories(health_dir_);
  open_reserve();
  // Not fatal: the start has checked the free space already (space_problems), and a file-size
  // limit (LimitFSIZE=) may forbid a file this large. Health then has the floor alone.
  if (!resize_reserve(kHealthReserveBytes)) {
    spdlog::warn(
        "health: cannot reserve {} MiB for the health files in {} ({}); tried again "
        "every second",
        kHealthReserveBytes >> 20, health_dir_.string(), std::strerror(errno));
  }
}

bool HealthRoom::resize_reserve(std::uint64_t size) noexcept {
  if (reserve_fd_ < 0) return false;
  if (size < reserve_size_) {
    if (::ftruncate(reserve_fd_, static_cast<off_t>(size)) != 0) return false;
  } else if (size > reserve_size_) {
    // fallocate allocates the blocks (a sparse file would reserve nothing); where the file system
    // has no fallocate, zeros are written instead.
    if (::fallocate(reserve_fd_, 0, 0, static_cast<off_t>(size)) != 0) {
      if (errno != EOPNOTSUPP) return false;
      static const char zeros[64 * 1024] = {};
      for (std::uint64_t at = reserve_size_; at < size; at += sizeof zeros) {
        const std::size_t n =
            static_cast<std::size_t>(std::min<std::uint64_t>(size - at, sizeof zeros));
        if (::pwrite(reserve_fd_, zeros, n, static_cast<off_t>(at)) != static_cast<ssize_t>(n)) {
          ::ftruncate(reserve_fd_, static_cast<off_t>(reserve_size_));
          return false;
        }
      }
    }
  }
  reserve_size_ = size;
  return true;
}

bool HealthRoom::allows(int handle, std::uint64_t bytes, std::string& reason) noexcept {
  Volume& v = volumes_[static_cast<std::size_t>(handle)];
  const std::int64_t now = monotonic_ns();
  if (v.checked_ns < 0 || now - v.checked_ns >= 100'000'000) {
    const auto free = free_bytes_at(v.directory);
    v.known = free.has_value();
    v.free = free.value_or(0);
    v.checked_ns = now;
  }
  if (!v.known) return true;  // cannot tell: the write itself will say
  if (v.free < bytes + kOutputFloorBytes && make_room_) {
    // The floor first (it removes the oldest of ours when the file system is short), then the
    // file system asked again: the estimate may be up to 100 ms old.
    make_room_(v.directory.native(), bytes);
    const auto free = free_bytes_at(v.directory);
    v.known = free.has_value();
    v.free = free.value_or(0);
    v.checked_ns = now;
    if (!v.known) return true;
  }
  if (v.free >= bytes + kOutputFloorBytes) {
    v.free -= bytes;
    return true;
  }
  reason.clear();
  fmt::format_to(std::back_inserter(reason),
                 "no space: {} MiB free on {} ({} MiB kept for the health files)", v.free >> 20,
                 v.directory.native(), kOutputFloorBytes >> 20);
  return false;
}

bool HealthRoom::release_piece() noexcept {
  if (reserve_size_ == 0) return false;
  const std::uint64_t size =
      reserve_size_ > kHealthReservePieceBytes ? reserve_size_ - kHealthReservePieceBytes : 0;
  if (!resize_reserve(size)) return false;
  spdlog::warn("health: the disk is full; {} KiB of the health reserve given back ({} KiB left)",
               kHealthReservePieceBytes >> 10, reserve_size_ >> 10);
  return true;
}

void HealthRoom::tend() noexcept {
  if (reserve_path_.empty()) return;
  if (reserve_fd_ >= 0) {
    // Removed with its directory (or the directory replaced): its blocks go back once closed.
    struct stat open_info {
    }, path_info{};
    const bool gone = ::fstat(reserve_fd_, &open_info) != 0 || open_info.st_nlink == 0 ||
                      ::stat(reserve_path_.c_str(), &path_info) != 0 ||
                      path_info.st_ino != open_info.st_ino || path_info.st_dev != open_info.st_dev;
    if (gone) {
      ::close(reserve_fd_);
      reserve_fd_ = -1;
      reserve_size_ = 0;
    }
  }
  if (reserve_fd_ < 0) {
    std::error_code ignored;
    std::filesystem::create_directories(health_dir_, ignored);
    try {
      open_reserve();
    } catch (const std::exception&) {
      return;  // tried again next second
    }
  }
  if (reserve_size_ >= kHealthReserveBytes) return;
  const auto free = free_bytes_at(health_dir_);
  const std::uint64_t missing = kHealthReserveBytes - reserve_size_;
  if (free && *free >= missing + kOutputFloorBytes) resize_reserve(kHealthReserveBytes);
}

void HealthRoom::remove() noexcept {
  if (reserve_fd_ < 0) return;
  ::close(reserve_fd_);
  reserve_fd_ = -1;
  ::unlink(reserve_path_.c_str());
}

}  // namespace pandarcap
