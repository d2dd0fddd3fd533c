// Heap allocations on the hot path, counted.
//
// The receive, decode and writer loops must not allocate once they are warm. Each loop marks its
// thread hot after a warm-up (mark_this_thread_hot); from then on every malloc/calloc/realloc/
// aligned allocation and every operator new made on that thread is counted, and the count is in
// the health output (`hot_path_allocations`), where the benchmark harness and the tests read it.
//
// The counting itself lives in allocation_hooks.cpp, which replaces the allocation functions in
// the pandarcapd executable only. Sanitizer builds keep their own allocator, so there nothing is
// counted and counting_available() is false, as in any binary without the hooks.
#pragma once

#include <cstdint>

namespace pandarcap::alloc {

enum class HotThread : int { kReceive = 0, kDecode = 1, kWriter = 2 };
inline constexpr int kHotThreads = 3;

void mark_this_thread_hot(HotThread thread) noexcept;
// Leaving the loop (shutdown: final flushes, renames, the last health record): stop counting.
void mark_this_thread_cold() noexcept;
std::uint64_t hot_allocations(HotThread thread) noexcept;
bool counting_available() noexcept;

// Called by the hooks.
void note_allocation() noexcept;

}  // namespace pandarcap::alloc
