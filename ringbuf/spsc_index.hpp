// SpscIndex: the index protocol shared by every single-producer single-consumer ring here
// (SlotRing for packets, SpscQueue for small typed messages). It owns no storage: it hands out
// positions, and the ring that uses it maps a position to its storage with `position & mask()`.
//
// Design (after rigtorp's SPSCQueue and the Linux kernel's kfifo):
// - Free-running positions: `tail` counts every item ever published, `head` every item ever
//   released. They are never reduced modulo the capacity, so full (tail - head == capacity) and
//   empty (tail == head) need no spare slot, and unsigned wrap-around at 2^64 is harmless.
// - The capacity is a power of two, so position -> slot is a mask, not a division.
// - Each side owns one cache line holding its own position and its cached copy of the other
//   side's position. A side reloads the other's position (one cache miss) only when its cache
//   says there is not enough room or data; in steady state each side touches only its own line
//   and the slots.
// - The read-only mask, the producer's line, the consumer's line and the sleep flag each sit on
//   their own cache line, so no write by one thread invalidates a line the other reads for free.
//
// Threading contract: exactly one producer thread calls reserve/publish/notify, exactly one
// consumer thread calls peek/release/wait_for_data. Either may call size_approx.
#pragma once

#include <algorithm>
#include <atomic>
#include <cassert>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <stdexcept>

#include "ringbuf/futex.hpp"
#include "ringbuf/ordering.hpp"

namespace pandarcap::ringbuf {

// 64 bytes on x86-64 and on the ARM64 cores a vehicle PC uses. (std::hardware_destructive_
// interference_size is not used: GCC warns that its value may change between compiler versions.)
inline constexpr std::size_t kCacheLine = 64;

// Positions [first, first + count) that are contiguous in storage: a ring never hands out a run
// that crosses the end of its storage, so the caller can pass the run to one recvmmsg or memcpy.
struct Run {
  std::size_t first = 0;
  std::size_t count = 0;
};

inline bool is_power_of_two(std::size_t n) noexcept {
  return n != 0 && (n & (n - 1)) == 0;
}

class SpscIndex {
 public:
  // How many times the consumer polls before it sleeps: about a microsecond, short enough not to
  // steal the producer's core when both threads share one.
  static constexpr int kSpinsBeforeSleep = 64;

  // `capacity` must be a power of two (1 is allowed). `initial_position` exists for tests of the
  // wrap-around at 2^64; real rings start at 0.
  explicit SpscIndex(std::size_t capacity, std::size_t initial_position = 0)
      : mask_(checked_capacity(capacity) - 1),
        tail_(initial_position),
        head_cache_(initial_position),
        head_(initial_position),
        tail_cache_(initial_position) {}

  SpscIndex(const SpscIndex&) = delete;
  SpscIndex& operator=(const SpscIndex&) = delete;

  std::size_t capacity() const noexcept { return mask_ + 1; }
  std::size_t mask() const noexcept { return mask_; }

  // ---- Producer ------------------------------------------------------------------------------

  // Up to `max` free positions starting at the producer's position, contiguous in storage.
  // A count of 0 means the ring is full: it returns at once, it never spins or blocks.
  Run reserve(std::size_t max) noexcept {
    const std::size_t tail = tail_.load(std::memory_order_relaxed);  // only this thread writes it
    std::size_t free = capacity() - (tail - head_cache_);
    if (free < max) {
      // acquire: the consumer's reads of the slots it released finish before we overwrite them.
      head_cache_ = head_.load(detail::kAcquire);
      free = capacity() - (tail - head_cache_);
    }
    const std::size_t to_end = capacity() - (tail & mask_);
    return {tail, std::min({max, free, to_end})};
  }

  // Makes the first `count` positions of the last reserve() visible to the consumer, in one store.
  void publish(std::size_t count) noexcept {
    const std::size_t tail = tail_.load(std::memory_order_relaxed);
    assert(count <= capacity() - (tail - head_cache_));
    // release: everything written into the slots happens before the consumer can see them.
    tail_.store(tail + count, detail::kRelease);
  }

  // Wakes the consumer if it sleeps in wait_for_data(). Call after publish(), once per batch:
  // it costs one locked instruction (a full barrier), which is why publish() does not do it.
  void notify() noexcept {
    // seq_cst RMW on tail_, then a seq_cst load of the flag: with the consumer's seq_cst store of
    // the flag and seq_cst load of tail_ (Dekker's pattern), at least one side sees the other, so
    // a consumer can never fall asleep on data it missed.
    tail_.fetch_add(0, std::memory_order_seq_cst);
    if (sleeping_.load(std::memory_order_seq_cst) != 0) {
      sleeping_.store(0, std::memory_order_relaxed);
      detail::futex_wake_all(sleeping_);
    }
  }

  // ---- Consumer ------------------------------------------------------------------------------

  // Up to `max` published positions starting at the consumer's position, contiguous in storage.
  // A count of 0 means the ring is empty.
  Run peek(std::size_t max) noexcept {
    const std::size_t head = head_.load(std::memory_order_relaxed);  // only this thread writes it
    std::size_t filled = tail_cache_ - head;
    if (filled < max) {
      // acquire: the producer's writes into the slots are visible before we read them.
      tail_cache_ = tail_.load(detail::kAcquire);
      filled = tail_cache_ - head;
    }
    const std::size_t to_end = capacity() - (head & mask_);
    return {head, std::min({max, filled, to_end})};
  }

  // Hands the first `count` positions of the last peek() back to the producer, in one store.
  void release(std::size_t count) noexcept {
    const std::size_t head = head_.load(std::memory_order_relaxed);
    assert(count <= tail_cache_ - head);
    // release: our reads of the slots happen before the producer may overwrite them.
    head_.store(head + count, detail::kRelease);
  }

  // Waits until the ring holds data, `timeout` passes, or a spurious wake-up; true if data is
  // there. Polls briefly first (data often follows within a microsecond at high rates), then
  // sleeps in the kernel so an idle consumer costs no CPU. A producer that publishes without
  // notify() still ends the wait by the timeout, never later.
  bool wait_for_data(std::chrono::nanoseconds timeout) noexcept {
    const std::size_t head = head_.load(std::memory_order_relaxed);
    for (int i = 0; i < kSpinsBeforeSleep; ++i) {
      // relaxed: only a hint; peek() does the acquire that makes the data readable.
      if (tail_.load(std::memory_order_relaxed) != head) return true;
      detail::cpu_relax();
    }
    sleeping_.store(1, std::memory_order_seq_cst);
    if (tail_.load(std::memory_order_seq_cst) == head) {
      // Sleeps only while the flag is still 1: a notify() in between makes this return at once.
      detail::futex_wait(sleeping_, 1, timeout);
    }
    sleeping_.store(0, std::memory_order_relaxed);
    return tail_.load(std::memory_order_relaxed) != head;
  }

  // ---- Either side ---------------------------------------------------------------------------

  // A snapshot that may be stale by the time it is used; for statistics, not for decisions.
  std::size_t size_approx() const noexcept {
    const std::size_t head = head_.load(std::memory_order_relaxed);
    const std::size_t tail = tail_.load(std::memory_order_relaxed);
    const std::size_t used = tail - head;
    return used > capacity() ? 0 : used;  // a torn pair of reads; "empty" is the safe answer
  }

 private:
  static std::size_t checked_capacity(std::size_t capacity) {
    if (!is_power_of_two(capacity)) {
      throw std::invalid_argument("ring capacity must be a power of two");
    }
    return capacity;
  }

  // Read-only after construction; alone on its line so the indices' writes never evict it.
  alignas(kCacheLine) const std::size_t mask_;

  // The producer's line.
  alignas(kCacheLine) std::atomic<std::size_t> tail_;
  std::size_t head_cache_;  // producer's last view of head_

  // The consumer's line.
  alignas(kCacheLine) std::atomic<std::size_t> head_;
  std::size_t tail_cache_;  // consumer's last view of tail_

  // Written only around a sleep, read by the producer's notify(): own line, so a busy consumer
  // moving head_ does not make every notify() miss.
  // (The class's alignment rounds its size up to whole lines, so the next object starts fresh.)
  alignas(kCacheLine) std::atomic<std::uint32_t> sleeping_{0};
};

}  // namespace pandarcap::ringbuf
