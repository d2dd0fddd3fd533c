#include "daemon/arena_memory.hpp"

#include <fmt/format.h>
#include <sys/mman.h>

#include <cerrno>
#include <cstring>
#include <system_error>

#if defined(__SANITIZE_ADDRESS__)
#include <sanitizer/asan_interface.h>
#endif

namespace pandarcap {

ArenaMemory::ArenaMemory(std::size_t bytes)
    : size_((bytes + kHugePage - 1) / kHugePage * kHugePage) {
  if (size_ == 0) size_ = kHugePage;
  // Mapped one huge page longer, then trimmed to an aligned start: mmap aligns to 4 KiB only.
  const std::size_t mapped = size_ + kHugePage;
  void* const p =
      ::mmap(nullptr, mapped, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  if (p == MAP_FAILED) {
    throw std::system_error(errno, std::generic_category(),
                            fmt::format("cannot map {} bytes of memory", mapped));
  }
  const auto start = reinterpret_cast<std::uintptr_t>(p);
  const std::uintptr_t aligned = (start + kHugePage - 1) / kHugePage * kHugePage;
  if (aligned > start) ::munmap(p, aligned - start);
  const std::size_t after = start + mapped - (aligned + size_);
  if (after > 0) ::munmap(reinterpret_cast<void*>(aligned + size_), after);
  data_ = reinterpret_cast<std::uint8_t*>(aligned);
  // Best effort: EINVAL where the kernel has no THP; the pages are then 4 KiB.
  (void)::madvise(data_, size_, MADV_HUGEPAGE);
  // Touched now, so no page fault waits in the decode thread later: populated by the kernel
  // (MADV_POPULATE_WRITE, Linux 5.14), which zero-fills each page as a first store would, with
  // no pass of stores over memory that is zero already. That pass was the largest part of a
  // sanitizer build's start (TSan instruments every byte of it: 0.25 of the 0.8 CPU-seconds a
  // TSan daemon took to start, and the tests start one hundreds of times). A kernel without it
  // (EINVAL) gets the stores; memory the kernel refuses now (ENOMEM) is an error here, with its
  // size, not a fault at a store later.
  if (::madvise(data_, bytes, MADV_POPULATE_WRITE) != 0) {
    if (errno != EINVAL) {
      const int error = errno;
      ::munmap(data_, size_);  // no destructor runs for an object that never was
      throw std::system_error(error, std::generic_category(),
                              fmt::format("cannot populate {} bytes of memory", bytes));
    }
    std::memset(data_, 0, bytes);
  }
}

void ArenaMemory::guard([[maybe_unused]] std::uint8_t* from,
                        [[maybe_unused]] std::size_t bytes) noexcept {
#if defined(__SANITIZE_ADDRESS__)
  ASAN_POISON_MEMORY_REGION(from, bytes);
#endif
}

ArenaMemory::~ArenaMemory() {
  if (data_ == nullptr) return;
#if defined(__SANITIZE_ADDRESS__)
  // The next mapping at these addresses starts clean.
  ASAN_UNPOISON_MEMORY_REGION(data_, size_);
#endif
  ::munmap(data_, size_);
}

}  // namespace pandarcap
