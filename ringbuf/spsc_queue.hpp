// SpscQueue<T>: a bounded single-producer single-consumer queue of small typed messages (frame
// handles going to the writer, empty arenas coming back), on the same SpscIndex protocol as the
// packet ring.
//
// Unlike SlotRing, elements have real lifetimes: try_emplace() constructs one in place, pop()
// destroys it, and the destructor destroys whatever is still queued, so every constructed element
// is destroyed exactly once. Storage for `capacity` elements is allocated once, at construction.
//
// Full queue: try_push()/try_emplace() return false at once (never spin, never block); the caller
// decides and counts. Empty queue: front() returns nullptr, try_pop() returns false.
#pragma once

#include <chrono>
#include <cstddef>
#include <memory>
#include <new>
#include <type_traits>
#include <utility>

#include "ringbuf/spsc_index.hpp"

namespace pandarcap::ringbuf {

template <typename T>
class SpscQueue {
 public:
  // Throws std::invalid_argument unless `capacity` is a power of two.
  explicit SpscQueue(std::size_t capacity, std::size_t initial_position = 0)
      : index_(capacity, initial_position), cells_(new Cell[capacity + 2 * kPaddingCells]) {}

  SpscQueue(const SpscQueue&) = delete;
  SpscQueue& operator=(const SpscQueue&) = delete;

  // Destroys the elements still queued. Call only when neither thread uses the queue any more.
  ~SpscQueue() {
    while (front() != nullptr)
      pop();
  }

  std::size_t capacity() const noexcept { return index_.capacity(); }

  // ---- Producer ------------------------------------------------------------------------------

  template <typename... Args>
  bool try_emplace(Args&&... args) noexcept(std::is_nothrow_constructible_v<T, Args&&...>) {
    const Run run = index_.reserve(1);
    if (run.count == 0) return false;
    // If the constructor throws, nothing was published and the slot stays free.
    ::new (static_cast<void*>(cell(run.first))) T(std::forward<Args>(args)...);
    index_.publish(1);
    return true;
  }
  bool try_push(const T& value) noexcept(std::is_nothrow_copy_constructible_v<T>) {
    return try_emplace(value);
  }
  bool try_push(T&& value) noexcept(std::is_nothrow_move_constructible_v<T>) {
    return try_emplace(std::move(value));
  }
  // Wakes the consumer if it sleeps in wait_for_data().
  void notify() noexcept { index_.notify(); }

  // ---- Consumer ------------------------------------------------------------------------------

  // The oldest element, or nullptr when empty. It stays valid until pop().
  T* front() noexcept {
    const Run run = index_.peek(1);
    if (run.count == 0) return nullptr;
    return std::launder(reinterpret_cast<T*>(cell(run.first)));
  }
  // Destroys the element front() returned and frees its slot. Only after a non-null front().
  void pop() noexcept {
    static_assert(std::is_nothrow_destructible_v<T>);
    const Run run = index_.peek(1);
    std::launder(reinterpret_cast<T*>(cell(run.first)))->~T();
    index_.release(1);
  }
  bool try_pop(T& out) noexcept(std::is_nothrow_move_assignable_v<T>) {
    T* element = front();
    if (element == nullptr) return false;
    out = std::move(*element);
    pop();
    return true;
  }
  bool wait_for_data(std::chrono::nanoseconds timeout) noexcept {
    return index_.wait_for_data(timeout);
  }

  std::size_t size_approx() const noexcept { return index_.size_approx(); }

 private:
  struct alignas(T) Cell {
    unsigned char bytes[sizeof(T)];
  };
  // Unused cells before and after the storage keep its first and last elements off the cache
  // lines of whatever the allocator placed next to it.
  static constexpr std::size_t kPaddingCells = (kCacheLine - 1) / sizeof(Cell) + 1;

  Cell* cell(std::size_t position) noexcept {
    return &cells_[kPaddingCells + (position & index_.mask())];
  }

  SpscIndex index_;
  std::unique_ptr<Cell[]> cells_;
};

}  // namespace pandarcap::ringbuf
