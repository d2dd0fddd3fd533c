#include "daemon/output/retention.hpp"

#include <sys/stat.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <cstring>
#include <optional>

#include "daemon/pcap/recording_sidecars.hpp"

namespace pandarcap {

void remove_sidecars(std::string_view recording_path) noexcept {
  const std::size_t slash = recording_path.rfind('/');
  const std::size_t name_at = slash == std::string_view::npos ? 0 : slash + 1;
  // A recording of ours (floor and retention list nothing else): its stem names its sidecars.
  const std::optional<std::string_view> found = recording_stem(recording_path);
  if (!found) return;
  const std::string_view stem = *found;
  std::array<char, 4096> path;  // on the stack: a path is at most PATH_MAX
  for (const std::string_view suffix : kSidecarSuffixes) {
    const std::size_t length = name_at + stem.size() + suffix.size();
    if (length >= path.size()) return;
    std::memcpy(path.data(), recording_path.data(), name_at + stem.size());
    std::memcpy(path.data() + name_at + stem.size(), suffix.data(), suffix.size());
    path[length] = '\0';
    ::unlink(path.data());  // none there: nothing to do
  }
}

std::size_t Retention::enforce() {
  const std::size_t before = files_.size();
  while (!files_.empty() && ((max_files_ != 0 && files_.size() > max_files_) ||
                             (max_bytes_ != 0 && bytes_ > max_bytes_))) {
    const FileList::Entry& oldest = files_.front();
    if (::unlink(oldest.path.c_str()) == 0) {
      remove_sidecars(oldest.path);
      if (on_removed_) on_removed_(oldest.path, oldest.value);
    }
    bytes_ -= oldest.value;
    files_.pop_front();
  }
  return before - files_.size();
}

void Retention::forget(std::string_view path) noexcept {
  if (const std::optional<std::uint64_t> bytes = files_.erase(path)) bytes_ -= *bytes;
}

void RecordedFiles::forget(std::string_view path) noexcept {
  files_.erase(path);
}

void RecordedFiles::add(std::string_view path, std::uint64_t items, const Retention& retention) {
  files_.push_back(path, items);
  if (retention.limited()) {
    while (files_.size() > retention.size())
      files_.pop_front();
  }
}

RecordedFiles::Gone RecordedFiles::take_gone() {
  Gone gone;
  for (std::size_t i = 0; i < files_.size(); ++i) {
    struct stat info;
    // A file that cannot be asked about (any error but ENOENT) counts as there.
    if (::stat(files_[i].path.c_str(), &info) == 0 || errno != ENOENT) continue;
    gone.items += files_[i].value;
    ++gone.files;
  }
  files_.clear();
  return gone;
}

}  // namespace pandarcap
