// The frame arenas' memory: one anonymous mapping for all of them (Pipeline), aligned to 2 MiB
// and offered to the kernel for transparent huge pages (madvise(MADV_HUGEPAGE)).
//
// Why: the writer hands each frame's points to the kernel with O_DIRECT (daemon/output/
// frame_output.cpp), and the kernel pins every page of the buffer for the I/O. With 4 KiB pages
// that is ~800 pins per frame, and `perf record` put the pinning (gup_fast_fallback) at 4.6 % of
// the daemon's samples at one sensor's rate; a huge page is pinned as one. The decoder's stores
// into the arena take fewer TLB misses too. Where the kernel has no huge page to give (THP off,
// memory fragmented) the mapping keeps 4 KiB pages: the same memory, nothing else changes.
#pragma once

#include <cstddef>
#include <cstdint>

namespace pandarcap {

class ArenaMemory {
 public:
  static constexpr std::size_t kHugePage = std::size_t{2} << 20;
  // `bytes`, zero-filled and touched: no page fault waits in the decode thread later. The mapping
  // is rounded up to whole huge pages; what lies past `bytes` is never touched (with huge pages,
  // the last one is whole: at most 2 MiB more than asked). Throws std::system_error (the
  // mapping or its pages refused: a memory limit, ENOMEM).
  explicit ArenaMemory(std::size_t bytes);
  ~ArenaMemory();
  ArenaMemory(const ArenaMemory&) = delete;
  ArenaMemory& operator=(const ArenaMemory&) = delete;

  // Marks `bytes` from `from` (inside this memory) as no arena's: an ASan build then reports any
  // access there, as it did when each arena was an allocation of its own. Nothing elsewhere.
  void guard(std::uint8_t* from, std::size_t bytes) noexcept;

  std::uint8_t* data() const noexcept { return data_; }
  std::size_t size() const noexcept { return size_; }

 private:
  std::uint8_t* data_ = nullptr;
  std::size_t size_ = 0;
};

}  // namespace pandarcap
