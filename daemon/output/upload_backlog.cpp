#include "daemon/output/upload_backlog.hpp"

#include <algorithm>
#include <cstring>
#include <limits>

#include "core/units.hpp"
#include "daemon/clocks.hpp"

namespace pandarcap {

UploadBacklog::UploadBacklog(bool enabled)
    : enabled_(enabled), dirent_buffer_(32 * 1024), reader_(dirent_buffer_) {}

void UploadBacklog::watch(const std::filesystem::path& directory) {
  directories_.push_back(directory);
}

void UploadBacklog::prepare() {
  step(std::numeric_limits<std::int64_t>::max() / 2);
}

void UploadBacklog::step(std::int64_t budget_ns) noexcept {
  const std::int64_t deadline = monotonic_ns() + budget_ns;
  if (!in_pass_) {
    in_pass_ = true;
    directory_ = 0;
    counting_ = Figures{};
  }
  std::uint32_t since_clock = 0;
  while (directory_ < directories_.size()) {
    // A directory that is not there (removed, not made yet) holds nothing to upload.
    if (!reader_.is_open() && !reader_.open(directories_[directory_].c_str())) {
      ++directory_;
      continue;
    }
    const auto ours = [](std::string_view name) { return upload_file_is_ours(name); };
    DirectoryReader::File file;
    while (reader_.next(file, ours)) {
      const std::int64_t mtime =
          static_cast<std::int64_t>(file.info.st_mtim.tv_sec) * kNsPerSecond +
          file.info.st_mtim.tv_nsec;
      if (counting_.files == 0 || mtime < counting_.oldest_mtime_ns)
        counting_.oldest_mtime_ns = mtime;
      ++counting_.files;
      counting_.bytes += static_cast<std::uint64_t>(file.info.st_size);
      // The clock is looked at every 64 files: a stat costs a microsecond or two.
      if (++since_clock == 64) {
        since_clock = 0;
        if (monotonic_ns() >= deadline) return;  // on from here at the next step
      }
    }
    ++directory_;  // read to its end (the reader has closed it)
  }
  published_ = counting_;
  known_ = true;
  in_pass_ = false;
}

void UploadBacklog::removed(std::string_view path, std::uint64_t bytes, Remover by) noexcept {
  const std::size_t slash = path.rfind('/');
  if (slash == std::string_view::npos) return;
  const std::string_view directory = path.substr(0, slash), name = path.substr(slash + 1);
  for (const std::filesystem::path& d : directories_) {
    if (d.native() != directory || !upload_file_is_ours(name)) continue;
    // It leaves the figures now, not at the end of the next pass.
    if (published_.files > 0) --published_.files;
    published_.bytes -= std::min(published_.bytes, bytes);
    if (!enabled_) return;
    ++files_removed_;
    bytes_removed_ += bytes;
    const std::size_t n = std::min(name.size(), sizeof last_removed_ - 1);
    std::memcpy(last_removed_, name.data(), n);
    last_removed_[n] = '\0';
    last_removed_by_floor_ = by == Remover::kFloor;
    return;
  }
}

void UploadBacklog::fill(std::int64_t now_realtime_ns, UploadGauges& gauges) const noexcept {
  gauges.enabled = enabled_;
  gauges.known = known_;
  gauges.backlog_bytes = published_.bytes;
  gauges.backlog_files = published_.files;
  // A file finished "later" than now (the clock set back since) is not waiting a negative time.
  gauges.oldest_seconds = published_.files == 0
                              ? 0
                              : static_cast<double>(std::max<std::int64_t>(
                                    now_realtime_ns - published_.oldest_mtime_ns, 0)) /
                                    1e9;
  std::memcpy(gauges.last_removed, last_removed_, sizeof last_removed_);
  gauges.last_removed_by_floor = last_removed_by_floor_;
}

}  // namespace pandarcap
