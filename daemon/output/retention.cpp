#include "daemon/output/retention.hpp"

#include <unistd.h>

#include <array>
#include <cstring>
#include <optional>
#include <system_error>

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
  std::uint64_t total = 0;
  for (const auto& file : files_)
    total += file.second;
  while (!files_.empty() && ((max_files_ != 0 && files_.size() > max_files_) ||
                             (max_bytes_ != 0 && total > max_bytes_))) {
    std::error_code ignored;
    const auto& [path, bytes] = files_.front();
    if (std::filesystem::remove(path, ignored)) {
      remove_sidecars(path.native());
      if (on_removed_) on_removed_(path.native(), bytes);
    }
    total -= bytes;
    files_.pop_front();
  }
  return before - files_.size();
}

void Retention::forget(std::string_view path) noexcept {
  for (auto it = files_.begin(); it != files_.end(); ++it) {
    if (it->first.native() == path) {
      files_.erase(it);
      return;
    }
  }
}

void RecordedFiles::forget(std::string_view path) noexcept {
  for (auto it = files_.begin(); it != files_.end(); ++it) {
    if (it->first == path) {
      files_.erase(it);
      return;
    }
  }
}

void RecordedFiles::add(std::string_view path, std::uint64_t items, const Retention& retention) {
  files_.emplace_back(path, items);
  if (retention.limited()) {
    while (files_.size() > retention.size())
      files_.pop_front();
  }
}

RecordedFiles::Gone RecordedFiles::take_gone() {
  Gone gone;
  for (const auto& [path, items] : files_) {
    std::error_code error;
    if (std::filesystem::exists(path, error) || error) continue;
    gone.items += items;
    ++gone.files;
  }
  files_.clear();
  return gone;
}

}  // namespace pandarcap
