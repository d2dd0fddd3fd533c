// The memory orders the rings use, in one place.
//
// Every acquire and release in ringbuf/ is spelled kAcquire / kRelease so that one compile-time
// switch can weaken them all to relaxed. Only the ThreadSanitizer negative-control test defines
// PANDARCAP_RINGBUF_NEGATIVE_CONTROL_RELAXED: it proves the stress tests would catch a ring that
// forgot its ordering. Never define it anywhere else.
#pragma once

#include <atomic>

namespace pandarcap::ringbuf::detail {

#if defined(PANDARCAP_RINGBUF_NEGATIVE_CONTROL_RELAXED)
inline constexpr std::memory_order kAcquire = std::memory_order_relaxed;
inline constexpr std::memory_order kRelease = std::memory_order_relaxed;
inline constexpr bool kNegativeControl = true;
#else
inline constexpr std::memory_order kAcquire = std::memory_order_acquire;
inline constexpr std::memory_order kRelease = std::memory_order_release;
inline constexpr bool kNegativeControl = false;
#endif

}  // namespace pandarcap::ringbuf::detail
