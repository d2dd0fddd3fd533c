#include "daemon/output/space_floor.hpp"

#include <dirent.h>
#include <fcntl.h>
#include <spdlog/spdlog.h>
#include <sys/stat.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

#include "core/units.hpp"

namespace pandarcap {
namespace {

// `name` is `prefix`, `field` '_'-separated fields, a number followed by '_' or '.', ..., `suffix`.
bool named_like(std::string_view name, std::string_view prefix, std::string_view suffix,
                int field) noexcept {
  if (!name.starts_with(prefix) || !name.ends_with(suffix)) return false;
  if (name.size() < prefix.size() + suffix.size() + 1) return false;
  name.remove_prefix(prefix.size());
  name.remove_suffix(suffix.size());
  for (int i = 0; i < field; ++i) {
    const std::size_t underscore = name.find('_');
    if (underscore == std::string_view::npos) return false;
    name.remove_prefix(underscore + 1);
  }
  std::size_t digits = 0;
  while (digits < name.size() && name[digits] >= '0' && name[digits] <= '9')
    ++digits;
  // The number ends the name (before the suffix) or is followed by more fields (_partial, _dupN).
  return digits > 0 && (digits == name.size() || name[digits] == '_');
}

// Which of two candidates is older: by modification time, then by name.
template <typename C>
bool older(const C& a, const C& b) noexcept {
  if (a.mtime_ns != b.mtime_ns) return a.mtime_ns < b.mtime_ns;
  return std::strcmp(a.name, b.name) < 0;
}

// The kernel's directory entry (getdents64): read without opendir, which allocates.
struct LinuxDirent64 {
  std::uint64_t d_ino;
  std::int64_t d_off;
  unsigned short d_reclen;
  unsigned char d_type;
  char d_name[1];
};

}  // namespace

bool floor_file_is_ours(FloorKind kind, std::string_view name) noexcept {
  switch (kind) {
    case FloorKind::kFrames:
      return named_like(name, "frame_", ".pcd", 0);
    case FloorKind::kRecordings:
      return named_like(name, "pandarcap_", ".pcap", 1) ||
             named_like(name, "pandarcap_", ".pcap.zst", 1);
    case FloorKind::kMcap:
      return named_like(name, "pandarcap_", ".mcap", 1);
    case FloorKind::kNone:
      return false;
  }
  return false;
}

SpaceFloor::SpaceFloor(std::uint64_t min_free_bytes, double min_free_percent)
    : min_free_bytes_(min_free_bytes), min_free_percent_(min_free_percent) {}

int SpaceFloor::watch(const std::filesystem::path& directory, FloorKind kind) {
  directories_.push_back(Directory{directory, kind});
  return static_cast<int>(directories_.size() - 1);
}

void SpaceFloor::prepare() {
  // Grouped by device: one statvfs, and one floor, per file system. A directory that cannot be
  // asked is a file system of its own.
  std::vector<dev_t> devices;
  for (std::size_t i = 0; i < directories_.size(); ++i) {
    struct stat info {};
    const bool known = ::stat(directories_[i].path.c_str(), &info) == 0;
    int volume = -1;
    if (known) {
      for (std::size_t v = 0; v < volumes_.size(); ++v) {
        if (devices[v] == info.st_dev) volume = static_cast<int>(v);
      }
    }
    if (volume < 0) {
      volume = static_cast<int>(volumes_.size());
      Volume added;
      added.first_directory = i;
      volumes_.push_back(added);
      // An unknown device never matches: its own file system.
      devices.push_back(known ? info.st_dev : static_cast<dev_t>(-1 - static_cast<long>(i)));
    }
    directories_[i].volume = volume;
  }
  if (enabled()) {
    candidates_.resize(kCandidates);
    dirent_buffer_.resize(32 * 1024);
    removed_path_.reserve(4096);
  }
}

std::optional<std::uint64_t> SpaceFloor::free_bytes(int handle) const noexcept {
  const Directory& d = directories_[static_cast<std::size_t>(handle)];
  if (d.volume < 0) return std::nullopt;
  const Volume& v = volumes_[static_cast<std::size_t>(d.volume)];
  if (!v.known) return std::nullopt;
  return v.space.free;
}

int SpaceFloor::file_system(int handle) const noexcept {
  return directories_[static_cast<std::size_t>(handle)].volume;
}

std::uint64_t SpaceFloor::floor_of(const FileSystemSpace& space) const noexcept {
  const auto percent =
      static_cast<std::uint64_t>(static_cast<double>(space.size) * min_free_percent_ / 100.0);
  return std::max(min_free_bytes_, percent);
}

std::optional<FileSystemSpace> SpaceFloor::ask(const std::filesystem::path& at) const noexcept {
  return query_ ? query_(at) : file_system_space_at(at);
}

void SpaceFloor::tend(std::int64_t now_ns) noexcept {
  for (std::size_t v = 0; v < volumes_.size(); ++v) {
    Volume& volume = volumes_[v];
    const std::filesystem::path& at = directories_[volume.first_directory].path;
    const auto space = ask(at);
    volume.known = space.has_value();
    if (!space) continue;
    volume.space = *space;
    if (!enabled()) continue;
    const std::uint64_t floor = floor_of(volume.space);
    bool unheld = false;
    // A few passes at most (kCandidates files each); the rest waits for the next second.
    for (int pass = 0; pass < 4 && volume.space.free < floor; ++pass) {
      scan(static_cast<int>(v));
      if (candidate_count_ == 0 || remove_oldest(static_cast<int>(v), floor) == 0) {
        unheld = true;
        break;
      }
      if (const auto after = ask(at)) volume.space = *after;
    }
    if (volume.files_unlogged != 0) log(volume, floor, now_ns, false);
    const bool unheld_logged_lately =
        volume.last_unheld_log_ns >= 0 && now_ns - volume.last_unheld_log_ns < 10 * kNsPerSecond;
    if (unheld && !unheld_logged_lately) {
      volume.last_unheld_log_ns = now_ns;
      spdlog::warn(
          "free-space floor: {} MiB free on the file system of {}, under the floor of {} "
          "MiB, and no file of ours left to remove: the disk is filled by something else",
          volume.space.free >> 20, at.native(), floor >> 20);
    }
  }
}

void SpaceFloor::scan(int volume) noexcept {
  candidate_count_ = 0;
  Candidate* const heap = candidates_.data();
  const auto newer = [](const Candidate& a, const Candidate& b) { return older(a, b); };
  for (std::size_t d = 0; d < directories_.size(); ++d) {
    const Directory& directory = directories_[d];
    if (directory.volume != volume || directory.kind == FloorKind::kNone) continue;
    const int fd = ::open(directory.path.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (fd < 0) continue;
    for (;;) {
      const long n = ::syscall(SYS_getdents64, fd, dirent_buffer_.data(), dirent_buffer_.size());
      if (n <= 0) break;
      for (long at = 0; at < n;) {
        const auto* entry = reinterpret_cast<const LinuxDirent64*>(dirent_buffer_.data() + at);
        at += entry->d_reclen;
        const std::string_view name(entry->d_name);
        // A link, a directory, a device: never ours, whatever its name.
        if (entry->d_type != DT_REG && entry->d_type != DT_UNKNOWN) continue;
        if (name.size() >= sizeof(Candidate::name) || !floor_file_is_ours(directory.kind, name))
          continue;
        struct stat info {};
        if (::fstatat(fd, entry->d_name, &info, AT_SYMLINK_NOFOLLOW) != 0 ||
            !S_ISREG(info.st_mode)) {
          continue;
        }
        Candidate c;
        c.mtime_ns =
            static_cast<std::int64_t>(info.st_mtim.tv_sec) * kNsPerSecond + info.st_mtim.tv_nsec;
        c.bytes = static_cast<std::uint64_t>(info.st_size);
        c.blocks_bytes = static_cast<std::uint64_t>(info.st_blocks) * 512;
        c.directory = static_cast<std::uint32_t>(d);
        std::memcpy(c.name, name.data(), name.size());
        c.name[name.size()] = '\0';
        // The oldest kCandidates: a max-heap whose top is the newest kept.
        if (candidate_count_ < kCandidates) {
          heap[candidate_count_++] = c;
          std::push_heap(heap, heap + candidate_count_, newer);
        } else if (older(c, heap[0])) {
          std::pop_heap(heap, heap + candidate_count_, newer);
          heap[candidate_count_ - 1] = c;
          std::push_heap(heap, heap + candidate_count_, newer);
        }
      }
    }
    ::close(fd);
  }
  std::sort_heap(heap, heap + candidate_count_, newer);  // oldest first
}

std::size_t SpaceFloor::remove_oldest(int v, std::uint64_t floor) noexcept {
  Volume& volume = volumes_[static_cast<std::size_t>(v)];
  std::uint64_t freed = 0;  // as the blocks the files held: what the file system gets back
  std::size_t removed = 0;
  for (std::size_t i = 0; i < candidate_count_ && volume.space.free + freed < floor; ++i) {
    const Candidate& c = candidates_[i];
    const Directory& directory = directories_[c.directory];
    removed_path_.assign(directory.path.native());
    removed_path_ += '/';
    removed_path_ += c.name;
    if (::unlink(removed_path_.c_str()) != 0) continue;  // gone already, or not ours to remove
    freed += c.blocks_bytes;
    ++removed;
    if (on_removed_) on_removed_(directory.kind, removed_path_);
    ++files_removed_;
    bytes_removed_ += c.bytes;
    ++volume.files_unlogged;
    volume.bytes_unlogged += c.bytes;
  }
  return removed;
}

void SpaceFloor::log(Volume& volume, std::uint64_t floor, std::int64_t now_ns,
                     bool force) noexcept {
  if (!force && volume.last_log_ns >= 0 && now_ns - volume.last_log_ns < 10 * kNsPerSecond) return;
  volume.last_log_ns = now_ns;
  spdlog::info(
      "free-space floor: {} of our oldest files removed ({} MiB) to keep {} MiB free on "
      "the file system of {} ({} MiB free now; {} removed since start)",
      volume.files_unlogged, volume.bytes_unlogged >> 20, floor >> 20,
      directories_[volume.first_directory].path.native(), volume.space.free >> 20, files_removed_);
  volume.files_unlogged = 0;
  volume.bytes_unlogged = 0;
}

}  // namespace pandarcap
