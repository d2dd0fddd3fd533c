#include "daemon/allocation_counter.hpp"

#include <atomic>

namespace pandarcap::alloc {

namespace {

// Static TLS in the executable: reading it never allocates, so the hooks may use it.
constinit thread_local int t_hot = -1;  // the HotThread this thread is, once warm
std::atomic<std::uint64_t> g_hot_allocations[kHotThreads]{};

}  // namespace

void mark_this_thread_hot(HotThread thread) noexcept {
  t_hot = static_cast<int>(thread);
}

void mark_this_thread_cold() noexcept {
  t_hot = -1;
}

std::uint64_t hot_allocations(HotThread thread) noexcept {
  return g_hot_allocations[static_cast<int>(thread)].load(std::memory_order_relaxed);
}

// Weak: pandarcapd's hooks (allocation_hooks.cpp) define the answer; a binary without them (the
// tests, the bench), which links the health publisher that asks, counts nothing.
[[gnu::weak]] bool counting_available() noexcept {
  return false;
}

void note_allocation() noexcept {
  if (t_hot >= 0) g_hot_allocations[t_hot].fetch_add(1, std::memory_order_relaxed);
}

}  // namespace pandarcap::alloc
