// The newest of a stream of messages, handed from one thread to one other without locks, waits
// or allocation: a triple buffer. The producer fills its own buffer and publishes it; the consumer
// takes the newest published one. A message the consumer had not taken when the next was
// published is replaced (the producer is told, to count it): the producer never waits for the
// consumer, and the consumer always gets the newest.
//
//   LatestMessage slot(capacity);       // three buffers of `capacity` bytes, reserved now
//   producer: std::vector<std::uint8_t>& b = slot.back(); b.clear(); b.push_back(...) ...;
//             bool replaced = slot.publish();
//   consumer: if (std::vector<std::uint8_t>* m = slot.take()) send(*m);
//
// The producer must keep back() within capacity() (push_back beyond it would allocate). The buffer
// take() returns is the consumer's until its next take(). Plain C++17: the live server's
// translation unit, which websocketpp keeps at C++17, includes it.
#pragma once

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace pandarcap::live {

class LatestMessage {
 public:
  explicit LatestMessage(std::size_t capacity_bytes) : capacity_(capacity_bytes) {
    for (std::vector<std::uint8_t>& buffer : buffers_)
      buffer.reserve(capacity_bytes);
  }
  LatestMessage(const LatestMessage&) = delete;
  LatestMessage& operator=(const LatestMessage&) = delete;

  std::size_t capacity() const noexcept { return capacity_; }

  // Producer: the buffer to fill next.
  std::vector<std::uint8_t>& back() noexcept { return buffers_[back_]; }
  // Producer: back() becomes the newest message. True when it replaced one never taken.
  bool publish() noexcept {
    const unsigned old = middle_.exchange(back_ | kFresh, std::memory_order_acq_rel);
    back_ = old & kIndex;
    return (old & kFresh) != 0;
  }

  // Consumer: the newest message if one was published since the last take, else null. The
  // consumer may change it (the server writes each client's subscription id into it).
  std::vector<std::uint8_t>* take() noexcept {
    if ((middle_.load(std::memory_order_acquire) & kFresh) == 0) return nullptr;
    const unsigned old = middle_.exchange(front_, std::memory_order_acq_rel);
    front_ = old & kIndex;
    return &buffers_[front_];
  }

 private:
  static constexpr unsigned kIndex = 3, kFresh = 4;
  std::size_t capacity_;
  std::array<std::vector<std::uint8_t>, 3> buffers_;
  unsigned back_ = 0;                            // the producer's
  alignas(64) unsigned front_ = 1;               // the consumer's
  alignas(64) std::atomic<unsigned> middle_{2};  // shared: an index, and kFresh
};

}  // namespace pandarcap::live
