// SlotRing<Slot>: a single-producer single-consumer ring of fixed slots that are allocated once,
// stay constructed for the ring's lifetime, and are filled and read in place (zero copy).
//
//   Producer                                   Consumer
//   auto free = ring.reserve(32);              if (!ring.wait_for_data(100ms)) tick();
//   n = recvmmsg(... into free[0..32) ...);    auto batch = ring.peek(32);
//   ring.publish(n);   // one release store    for (Slot& s : batch) decode(s);
//   ring.notify();     // once per batch       ring.release(batch.size());  // one store
//
// Full ring policy: DROP NEWEST, COUNTED. reserve() returns an empty span at once when no slot is
// free; it never spins, blocks or overwrites a slot the consumer has not released. The producer
// must then discard the datagram (e.g. receive it into a scratch buffer) and count the overrun.
// Dropping the newest keeps every packet already queued in order, so the decoder's frames stay
// whole up to the overrun.
//
// A span never crosses the end of the storage, so near the wrap a reserve() or peek() can return
// fewer slots than are free or filled; call again for the rest.
#pragma once

#include <chrono>
#include <cstddef>
#include <memory>
#include <span>

#include "ringbuf/spsc_index.hpp"

namespace pandarcap::ringbuf {

template <typename Slot>
class SlotRing {
 public:
  // Allocates and value-initialises every slot now (which also faults the pages in), so nothing is
  // allocated or first-touched on the hot path. Throws std::invalid_argument unless `capacity` is a
  // power of two.
  explicit SlotRing(std::size_t capacity, std::size_t initial_position = 0)
      : index_(capacity, initial_position), slots_(new Slot[capacity]()) {}

  std::size_t capacity() const noexcept { return index_.capacity(); }

  // Producer: up to `max` free slots to fill in place; empty when the ring is full.
  std::span<Slot> reserve(std::size_t max) noexcept { return slots(index_.reserve(max)); }
  // Producer: the first `count` reserved slots are ready for the consumer.
  void publish(std::size_t count) noexcept { index_.publish(count); }
  // Producer: wakes a sleeping consumer (one locked instruction; call once per batch).
  void notify() noexcept { index_.notify(); }

  // Consumer: up to `max` filled slots, oldest first; empty when the ring is empty.
  std::span<Slot> peek(std::size_t max) noexcept { return slots(index_.peek(max)); }
  // Consumer: the first `count` peeked slots may be reused by the producer.
  void release(std::size_t count) noexcept { index_.release(count); }
  // Consumer: spin briefly, then sleep until data, notify() or `timeout`; true if data is there.
  bool wait_for_data(std::chrono::nanoseconds timeout) noexcept {
    return index_.wait_for_data(timeout);
  }

  std::size_t size_approx() const noexcept { return index_.size_approx(); }

 private:
  std::span<Slot> slots(Run run) noexcept {
    return {slots_.get() + (run.first & index_.mask()), run.count};
  }

  SpscIndex index_;
  std::unique_ptr<Slot[]> slots_;
};

}  // namespace pandarcap::ringbuf
