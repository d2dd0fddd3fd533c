#include "daemon/output/retention.hpp"

#include <system_error>

namespace pandarcap {

std::size_t Retention::enforce() {
  const std::size_t before = files_.size();
  std::uint64_t total = 0;
  for (const auto& file : files_)
    total += file.second;
  while (!files_.empty() && ((max_files_ != 0 && files_.size() > max_files_) ||
                             (max_bytes_ != 0 && total > max_bytes_))) {
    std::error_code ignored;
    std::filesystem::remove(files_.front().first, ignored);
    total -= files_.front().second;
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
