// A first-in first-out list of file paths, each with a number (its bytes, its packets), that
// allocates only while it grows: a ring of slots whose strings keep their capacity when their
// file leaves the list, so the next path of the same length (ours all are, or nearly) is copied
// into memory that is already there. Retention adds a file and removes one for every frame at
// steady state; with std::deque<std::string> that was about 3 allocations a frame in the writer
// (24 067 in a 60 s soak). Owned by one thread.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace pandarcap {

class FileList {
 public:
  struct Entry {
    std::string path;
    std::uint64_t value = 0;
  };

  std::size_t size() const noexcept { return count_; }
  bool empty() const noexcept { return count_ == 0; }
  // The i-th file, oldest first.
  const Entry& operator[](std::size_t i) const noexcept {
    return slots_[(head_ + i) % slots_.size()];
  }
  const Entry& front() const noexcept { return (*this)[0]; }

  // The newest file. Allocates only when every slot is taken (the ring doubles) or when `path`
  // is longer than any the slot held before.
  void push_back(std::string_view path, std::uint64_t value) {
    if (count_ == slots_.size()) grow();
    Entry& slot = slots_[(head_ + count_) % slots_.size()];
    slot.path.assign(path);
    slot.value = value;
    ++count_;
  }
  // The oldest file off the list; its slot keeps its string's memory.
  void pop_front() noexcept {
    head_ = (head_ + 1) % slots_.size();
    --count_;
  }
  // The first (oldest) file named `path` off the list, the later ones moving up one slot (their
  // strings swapped, not copied). Returns its number if it was listed. Allocates nothing.
  std::optional<std::uint64_t> erase(std::string_view path) noexcept {
    for (std::size_t i = 0; i < count_; ++i) {
      if (slot(i).path != path) continue;
      const std::uint64_t value = slot(i).value;
      for (std::size_t j = i; j + 1 < count_; ++j)
        std::swap(slot(j), slot(j + 1));
      --count_;
      return value;
    }
    return std::nullopt;
  }
  void clear() noexcept { head_ = count_ = 0; }
  // Room made now (at start-up) for `slots` files whose paths are up to `path_bytes` long: the
  // first that many allocate nothing when they come. Never shrinks.
  void reserve(std::size_t slots, std::size_t path_bytes) {
    if (slots > slots_.size()) grow(slots);
    for (Entry& entry : slots_)
      entry.path.reserve(path_bytes);
  }

 private:
  Entry& slot(std::size_t i) noexcept { return slots_[(head_ + i) % slots_.size()]; }
  void grow(std::size_t at_least = 0) {
    std::vector<Entry> bigger(std::max(at_least, slots_.empty() ? 16 : 2 * slots_.size()));
    for (std::size_t i = 0; i < count_; ++i)
      bigger[i] = std::move(slot(i));
    slots_ = std::move(bigger);
    head_ = 0;
  }

  std::vector<Entry> slots_;
  std::size_t head_ = 0, count_ = 0;
};

}  // namespace pandarcap
