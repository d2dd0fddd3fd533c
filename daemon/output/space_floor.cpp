#include "daemon/output/space_floor.hpp"

#include <spdlog/spdlog.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

#include "core/units.hpp"
#include "daemon/output/directory_reader.hpp"
#include "daemon/output/retention.hpp"

namespace pandarcap {
namespace {

// Which of two candidates is older: by modification time, then by name.
template <typename C>
bool older(const C& a, const C& b) noexcept {
  if (a.mtime_ns != b.mtime_ns) return a.mtime_ns < b.mtime_ns;
  return std::strcmp(a.name, b.name) < 0;
}

}  // namespace

std::uint64_t minimum_floor_bytes(std::uint64_t reserve_bytes, double bytes_per_second) noexcept {
  const double writing = std::max(bytes_per_second, 0.0) * 2;
  return reserve_bytes + static_cast<std::uint64_t>(std::min(writing, 1e18));
}

SpaceFloor::SpaceFloor(std::uint64_t min_free_bytes, double min_free_percent,
                       std::uint64_t reserve_bytes)
    : min_free_bytes_(min_free_bytes),
      min_free_percent_(min_free_percent),
      reserve_bytes_(reserve_bytes),
      minimum_(minimum_floor_bytes(reserve_bytes, 0)) {}

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

std::uint64_t SpaceFloor::configured_floor(const FileSystemSpace& space) const noexcept {
  const auto percent =
      static_cast<std::uint64_t>(static_cast<double>(space.size) * min_free_percent_ / 100.0);
  return std::max(min_free_bytes_, percent);
}

std::uint64_t SpaceFloor::floor_of(const FileSystemSpace& space) const noexcept {
  const std::uint64_t configured = configured_floor(space);
  return reserve_bytes_ == 0 ? configured : std::max(configured, minimum_);
}

std::uint64_t SpaceFloor::floor_bytes(int handle) const noexcept {
  const Directory& d = directories_[static_cast<std::size_t>(handle)];
  if (d.volume < 0) return 0;
  const Volume& v = volumes_[static_cast<std::size_t>(d.volume)];
  return v.known ? floor_of(v.space) : 0;
}

void SpaceFloor::write_rate(double bytes_per_second, std::int64_t now_ns) noexcept {
  if (reserve_bytes_ == 0) return;
  const std::uint64_t minimum = minimum_floor_bytes(reserve_bytes_, bytes_per_second);
  if (minimum <= minimum_) return;
  minimum_ = minimum;
  rate_ = bytes_per_second;
  log_minimum(now_ns);
}

void SpaceFloor::log_minimum(std::int64_t now_ns) noexcept {
  // Said at the start, then when it has grown by an eighth since last said (the rate wanders by a
  // few per cent from second to second), at most every 10 s after the first rise; and only where
  // it is above the configured floor.
  const bool grown = minimum_ > minimum_logged_ + minimum_logged_ / 8;
  const bool logged_lately =
      last_minimum_log_ns_ >= 0 && now_ns - last_minimum_log_ns_ < 10 * kNsPerSecond;
  if (!grown || logged_lately) return;
  for (const Volume& volume : volumes_) {
    if (!volume.known || configured_floor(volume.space) >= minimum_) continue;
    const std::string& at = directories_[volume.first_directory].path.native();
    if (rate_ == 0) {
      spdlog::info(
          "free-space floor: output.min_free_bytes / min_free_percent ({} MiB on the file system "
          "of {}) is below the {} MiB kept for the health files plus 2 s of writing: the floor is "
          "raised to that, {} MiB now, and rises with the measured write rate",
          configured_floor(volume.space) >> 20, at, reserve_bytes_ >> 20, minimum_ >> 20);
    } else {
      last_minimum_log_ns_ = now_ns;
      // Short (the writer's loop logs it): spdlog formats up to 250 bytes without allocating.
      spdlog::info(
          "free-space floor: raised to {} MiB on {}: {} MiB for the health files plus 2 s at "
          "{:.1f} MB/s (configured: {} MiB)",
          minimum_ >> 20, at, reserve_bytes_ >> 20, rate_ / 1e6,
          configured_floor(volume.space) >> 20);
    }
    minimum_logged_ = minimum_;
    return;
  }
}

std::optional<FileSystemSpace> SpaceFloor::ask(const std::filesystem::path& at) const noexcept {
  return query_ ? query_(at) : file_system_space_at(at);
}

void SpaceFloor::tend(std::int64_t now_ns) noexcept {
  const bool first = !tended_;
  tended_ = true;
  for (std::size_t v = 0; v < volumes_.size(); ++v) {
    Volume& volume = volumes_[v];
    const std::filesystem::path& at = directories_[volume.first_directory].path;
    const auto space = ask(at);
    volume.known = space.has_value();
    if (!space) continue;
    volume.space = *space;
    if (!enabled()) continue;
    const std::uint64_t floor = floor_of(volume.space);
    const bool unheld = !hold(static_cast<int>(v), floor);
    if (volume.files_unlogged != 0) log(volume, floor, now_ns, false);
    const bool unheld_logged_lately =
        volume.last_unheld_log_ns >= 0 && now_ns - volume.last_unheld_log_ns < 10 * kNsPerSecond;
    if (unheld && !unheld_logged_lately) {
      volume.last_unheld_log_ns = now_ns;
      spdlog::warn(
          "free-space floor: {} MiB free on the file system of {}, under the floor of {} "
          "MiB, and no finished file of ours left to remove: the disk is filled by something "
          "else, or by the open recordings (.part; see pcap_rotate_seconds)",
          volume.space.free >> 20, at.native(), floor >> 20);
    }
  }
  if (first && reserve_bytes_ != 0) log_minimum(now_ns);
}

bool SpaceFloor::hold(int v, std::uint64_t floor) noexcept {
  Volume& volume = volumes_[static_cast<std::size_t>(v)];
  const std::filesystem::path& at = directories_[volume.first_directory].path;
  // A few passes at most (kCandidates files each); the rest waits for the next second.
  for (int pass = 0; pass < 4 && volume.space.free < floor; ++pass) {
    // The oldest found by the last scan are still the oldest (what came since is newer): the
    // directories are read again only when they are used up, or turn out to be gone.
    bool fresh = false;
    if (candidate_volume_ != v || next_candidate_ >= candidate_count_) {
      scan(v);
      fresh = true;
    }
    if (remove_oldest(v, floor) == 0) {
      if (fresh) return false;  // none of ours left
      candidate_count_ = 0;     // all gone already: read the directories again
      continue;
    }
    if (const auto after = ask(at)) volume.space = *after;
  }
  return true;
}

bool SpaceFloor::make_room(std::string_view directory, std::uint64_t bytes,
                           std::int64_t now_ns) noexcept {
  if (!enabled()) return false;
  for (const Directory& d : directories_) {
    if (d.kind == FloorKind::kNone || d.volume < 0 || d.path.native() != directory) continue;
    Volume& volume = volumes_[static_cast<std::size_t>(d.volume)];
    const auto space = ask(directories_[volume.first_directory].path);
    if (!space) return false;
    volume.known = true;
    volume.space = *space;
    // Room for the write above the guard's reserve, with the floor's 2 s of writing too.
    const std::uint64_t floor = std::max(floor_of(volume.space), minimum_ + bytes);
    const std::uint64_t before = files_removed_;
    hold(d.volume, floor);
    if (volume.files_unlogged != 0) log(volume, floor, now_ns, false);
    return files_removed_ != before;
  }
  return false;
}

void SpaceFloor::scan(int volume) noexcept {
  candidate_count_ = 0;
  next_candidate_ = 0;
  candidate_volume_ = volume;
  Candidate* const heap = candidates_.data();
  const auto newer = [](const Candidate& a, const Candidate& b) { return older(a, b); };
  DirectoryReader reader(dirent_buffer_);
  for (std::size_t d = 0; d < directories_.size(); ++d) {
    const Directory& directory = directories_[d];
    if (directory.volume != volume || directory.kind == FloorKind::kNone) continue;
    if (!reader.open(directory.path.c_str())) continue;
    const auto ours = [&directory](std::string_view name) {
      return name.size() < sizeof(Candidate::name) && floor_file_is_ours(directory.kind, name);
    };
    DirectoryReader::File file;
    while (reader.next(file, ours)) {
      const struct stat& info = file.info;
      Candidate c;
      c.mtime_ns =
          static_cast<std::int64_t>(info.st_mtim.tv_sec) * kNsPerSecond + info.st_mtim.tv_nsec;
      c.bytes = static_cast<std::uint64_t>(info.st_size);
      c.blocks_bytes = static_cast<std::uint64_t>(info.st_blocks) * 512;
      c.directory = static_cast<std::uint32_t>(d);
      std::memcpy(c.name, file.name.data(), file.name.size());
      c.name[file.name.size()] = '\0';
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
  std::sort_heap(heap, heap + candidate_count_, newer);  // oldest first
}

std::size_t SpaceFloor::remove_oldest(int v, std::uint64_t floor) noexcept {
  Volume& volume = volumes_[static_cast<std::size_t>(v)];
  std::uint64_t freed = 0;  // as the blocks the files held: what the file system gets back
  std::size_t removed = 0;
  for (; next_candidate_ < candidate_count_ && volume.space.free + freed < floor;
       ++next_candidate_) {
    const Candidate& c = candidates_[next_candidate_];
    const Directory& directory = directories_[c.directory];
    removed_path_.assign(directory.path.native());
    removed_path_ += '/';
    removed_path_ += c.name;
    if (::unlink(removed_path_.c_str()) != 0) continue;  // gone already, or not ours to remove
    freed += c.blocks_bytes;
    ++removed;
    if (directory.kind == FloorKind::kRecordings) remove_sidecars(removed_path_);
    if (on_removed_) on_removed_(directory.kind, removed_path_, c.bytes);
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
