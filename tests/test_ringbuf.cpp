// Single-threaded contract of the SPSC rings: capacities, full and empty edges, contiguous runs at
// the wrap of the storage, wrap-around of the free-running positions at 2^64, element lifetimes
// in the typed queue, and the consumer's timed wait and wake-up.
#include <atomic>
#include <catch2/catch.hpp>
#include <chrono>
#include <cstdint>
#include <limits>
#include <memory>
#include <set>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "daemon/packet_slot.hpp"
#include "ringbuf/spsc_queue.hpp"

using namespace pandarcap::ringbuf;
using pandarcap::kMaxAcceptedDatagram;
using pandarcap::PacketRing;
using pandarcap::PacketSlot;
using namespace std::chrono_literals;

namespace {

constexpr std::size_t kNearLimit = std::numeric_limits<std::size_t>::max() - 5;

// Pushes `values` one at a time through reserve/publish.
template <typename Ring>
void push_one(Ring& ring, std::uint32_t value) {
  auto slots = ring.reserve(1);
  REQUIRE(slots.size() == 1);
  slots[0].length = value;
  ring.publish(1);
}

template <typename Ring>
std::uint32_t pop_one(Ring& ring) {
  auto slots = ring.peek(1);
  REQUIRE(slots.size() == 1);
  const std::uint32_t value = slots[0].length;
  ring.release(1);
  return value;
}

// Counts constructions and destructions, and catches a destroy of a dead or never-built object.
struct Tracked {
  static inline int constructed = 0;
  static inline int destroyed = 0;
  static inline int bad_destroys = 0;
  static inline std::set<const Tracked*> alive;
  static inline bool throw_next = false;

  int value = 0;
  explicit Tracked(int v) : value(v) {
    if (throw_next) {
      throw_next = false;
      throw std::runtime_error("constructor failed");
    }
    born();
  }
  Tracked(const Tracked& other) : value(other.value) { born(); }
  Tracked(Tracked&& other) noexcept : value(other.value) { born(); }
  Tracked& operator=(const Tracked&) = default;
  Tracked& operator=(Tracked&&) noexcept = default;
  ~Tracked() {
    ++destroyed;
    if (alive.erase(this) != 1) ++bad_destroys;
  }
  static void reset() {
    constructed = destroyed = bad_destroys = 0;
    alive.clear();
    throw_next = false;
  }

 private:
  void born() {
    ++constructed;
    alive.insert(this);
  }
};

}  // namespace

TEST_CASE("capacity must be a power of two", "[ringbuf]") {
  for (std::size_t bad : {0u, 3u, 5u, 6u, 100u, 4095u}) {
    INFO("capacity " << bad);
    CHECK_THROWS_AS(PacketRing(bad), std::invalid_argument);
    CHECK_THROWS_AS(SpscQueue<int>(bad), std::invalid_argument);
  }
  for (std::size_t good : {1u, 2u, 4u, 1024u, 4096u}) {
    PacketRing ring(good);
    CHECK(ring.capacity() == good);
    SpscQueue<int> queue(good);
    CHECK(queue.capacity() == good);
  }
}

TEST_CASE("packet slots are whole cache lines and cache-line aligned", "[ringbuf]") {
  PacketRing ring(8);
  auto slots = ring.reserve(8);
  REQUIRE(slots.size() == 8);
  for (const PacketSlot& slot : slots) {
    CHECK(reinterpret_cast<std::uintptr_t>(&slot) % kCacheLine == 0);
  }
  CHECK(sizeof(PacketSlot) % kCacheLine == 0);
  CHECK(PacketSlot::kPayloadCapacity >= kMaxAcceptedDatagram);
}

TEST_CASE("empty and full edges", "[ringbuf]") {
  SECTION("capacity 1") {
    PacketRing ring(1);
    CHECK(ring.peek(1).empty());
    CHECK(ring.reserve(5).size() == 1);
    push_one(ring, 7);
    CHECK(ring.reserve(1).empty());  // full: told at once
    CHECK(ring.size_approx() == 1);
    CHECK(pop_one(ring) == 7);
    CHECK(ring.peek(1).empty());
    CHECK(ring.size_approx() == 0);
    CHECK(ring.reserve(1).size() == 1);
  }
  SECTION("fill to capacity, drain, refill") {
    PacketRing ring(8);
    for (std::uint32_t i = 0; i < 8; ++i)
      push_one(ring, i);
    CHECK(ring.reserve(1).empty());
    CHECK(ring.reserve(100).empty());
    CHECK(ring.size_approx() == 8);
    for (std::uint32_t i = 0; i < 8; ++i)
      CHECK(pop_one(ring) == i);
    CHECK(ring.peek(100).empty());
    CHECK(ring.reserve(100).size() == 8);
  }
  SECTION("a zero-sized request hands out nothing and publish(0)/release(0) change nothing") {
    PacketRing ring(4);
    CHECK(ring.reserve(0).empty());
    ring.publish(0);
    CHECK(ring.peek(4).empty());
    push_one(ring, 1);
    CHECK(ring.peek(0).empty());
    ring.release(0);
    CHECK(ring.size_approx() == 1);
  }
  SECTION("a partial publish leaves the rest of the reservation free") {
    PacketRing ring(8);
    auto slots = ring.reserve(8);
    REQUIRE(slots.size() == 8);
    slots[0].length = 10;
    slots[1].length = 11;
    ring.publish(2);  // recvmmsg filled only two
    CHECK(ring.peek(8).size() == 2);
    CHECK(ring.reserve(8).size() == 6);
  }
  SECTION("a partial release keeps the rest for the next peek") {
    PacketRing ring(8);
    for (std::uint32_t i = 0; i < 5; ++i)
      push_one(ring, i);
    auto batch = ring.peek(8);
    REQUIRE(batch.size() == 5);
    ring.release(2);
    auto rest = ring.peek(8);
    REQUIRE(rest.size() == 3);
    CHECK(rest[0].length == 2);
  }
}

TEST_CASE("runs never cross the end of the storage", "[ringbuf]") {
  PacketRing ring(8);
  // Move both positions to 6: two slots before the end of storage.
  for (std::uint32_t i = 0; i < 6; ++i)
    push_one(ring, i);
  for (std::uint32_t i = 0; i < 6; ++i)
    pop_one(ring);
  auto first = ring.reserve(8);
  CHECK(first.size() == 2);  // 8 are free, only 2 are contiguous
  first[0].length = 100;
  first[1].length = 101;
  ring.publish(2);
  auto second = ring.reserve(8);
  CHECK(second.size() == 6);                 // the rest, from the start of storage
  CHECK(second.data() + 6 == first.data());  // the run after the wrap starts at slot 0
  for (std::size_t i = 0; i < 6; ++i)
    second[i].length = static_cast<std::uint32_t>(102 + i);
  ring.publish(6);
  CHECK(ring.reserve(1).empty());
  auto a = ring.peek(8);
  CHECK(a.size() == 2);
  CHECK(a[0].length == 100);
  ring.release(2);
  auto b = ring.peek(8);
  REQUIRE(b.size() == 6);
  CHECK(b[0].length == 102);
  CHECK(b[5].length == 107);
}

TEST_CASE("positions wrap around 2^64 without losing or reordering anything", "[ringbuf]") {
  SECTION("packet ring, capacity 4") {
    PacketRing ring(4, kNearLimit);
    std::uint32_t next_in = 0;
    std::uint32_t next_out = 0;
    // 40 items in bursts of 3 carry the positions across the limit several slots deep.
    for (int burst = 0; burst < 13; ++burst) {
      for (int i = 0; i < 3; ++i)
        push_one(ring, next_in++);
      CHECK(ring.size_approx() == 3);
      CHECK(ring.reserve(4).size() <= 1);
      for (int i = 0; i < 3; ++i)
        CHECK(pop_one(ring) == next_out++);
    }
    CHECK(next_out == 39);
  }
  SECTION("full and empty are still recognised across the limit") {
    PacketRing ring(4, std::numeric_limits<std::size_t>::max() - 1);
    for (std::uint32_t i = 0; i < 4; ++i)
      push_one(ring, i);  // positions max-1 .. max+2
    CHECK(ring.reserve(1).empty());
    CHECK(ring.size_approx() == 4);
    for (std::uint32_t i = 0; i < 4; ++i)
      CHECK(pop_one(ring) == i);
    CHECK(ring.peek(1).empty());
    CHECK(ring.size_approx() == 0);
  }
  SECTION("typed queue, capacity 2") {
    SpscQueue<std::string> queue(2, kNearLimit);
    for (int i = 0; i < 20; ++i) {
      REQUIRE(queue.try_push(std::to_string(i)));
      REQUIRE(queue.try_emplace(std::to_string(i) + "b"));
      CHECK_FALSE(queue.try_push("overflow"));
      std::string out;
      REQUIRE(queue.try_pop(out));
      CHECK(out == std::to_string(i));
      REQUIRE(queue.front() != nullptr);
      CHECK(*queue.front() == std::to_string(i) + "b");
      queue.pop();
      CHECK(queue.front() == nullptr);
    }
  }
}

TEST_CASE("typed queue: every constructed element is destroyed exactly once", "[ringbuf]") {
  Tracked::reset();
  SECTION("pushed, popped, and some left in the queue when it is destroyed") {
    {
      SpscQueue<Tracked> queue(8);
      for (int i = 0; i < 6; ++i)
        REQUIRE(queue.try_emplace(i));
      Tracked out(-1);
      REQUIRE(queue.try_pop(out));
      CHECK(out.value == 0);
      REQUIRE(queue.front() != nullptr);
      CHECK(queue.front()->value == 1);
      queue.pop();
      Tracked copy(42);
      REQUIRE(queue.try_push(copy));         // copy-constructed into the queue
      REQUIRE(queue.try_push(Tracked(43)));  // move-constructed into the queue
      CHECK(queue.size_approx() == 6);
      CHECK(Tracked::alive.size() == 6 + 2);  // 6 queued + out + copy
    }
    CHECK(Tracked::constructed == Tracked::destroyed);
    CHECK(Tracked::alive.empty());
    CHECK(Tracked::bad_destroys == 0);
  }
  SECTION("wrapping many times: no element outlives its pop") {
    {
      SpscQueue<Tracked> queue(4);
      for (int i = 0; i < 1000; ++i) {
        REQUIRE(queue.try_emplace(i));
        if (i % 3 != 0) {
          REQUIRE(queue.front() != nullptr);
          queue.pop();
        }
        CHECK(Tracked::alive.size() == queue.size_approx());
        if (queue.size_approx() == 4) {
          CHECK_FALSE(queue.try_emplace(-1));  // full: nothing constructed
          while (queue.front() != nullptr)
            queue.pop();
        }
      }
    }
    CHECK(Tracked::constructed == Tracked::destroyed);
    CHECK(Tracked::bad_destroys == 0);
  }
  SECTION("a throwing constructor publishes nothing and leaks nothing") {
    {
      SpscQueue<Tracked> queue(2);
      REQUIRE(queue.try_emplace(1));
      Tracked::throw_next = true;
      CHECK_THROWS_AS(queue.try_emplace(2), std::runtime_error);
      CHECK(queue.size_approx() == 1);
      REQUIRE(queue.try_emplace(3));  // the slot the failed element would have used is free
      CHECK(queue.front()->value == 1);
      queue.pop();
      CHECK(queue.front()->value == 3);
    }
    CHECK(Tracked::constructed == Tracked::destroyed);
    CHECK(Tracked::bad_destroys == 0);
  }
}

TEST_CASE("typed queue: move-only elements", "[ringbuf]") {
  SpscQueue<std::unique_ptr<int>> queue(4);
  REQUIRE(queue.try_push(std::make_unique<int>(5)));
  std::unique_ptr<int> out;
  REQUIRE(queue.try_pop(out));
  REQUIRE(out != nullptr);
  CHECK(*out == 5);
  CHECK_FALSE(queue.try_pop(out));
  CHECK(*out == 5);  // a failed pop leaves the target alone
}

TEST_CASE("consumer wait: times out when empty, returns at once with data", "[ringbuf]") {
  PacketRing ring(4);
  CHECK_FALSE(ring.wait_for_data(1ms));
  CHECK_FALSE(ring.wait_for_data(0ns));
  push_one(ring, 9);
  CHECK(ring.wait_for_data(1h));  // would hang the suite if it slept on available data
  CHECK(pop_one(ring) == 9);
}

TEST_CASE("consumer wait: notify wakes a sleeping consumer long before its timeout",
          "[ringbuf][threads]") {
  PacketRing ring(4);
  std::atomic<bool> woke{false};
  std::atomic<bool> had_data{false};
  const auto start = std::chrono::steady_clock::now();
  std::thread consumer([&] {
    // A one-minute timeout: only notify() can end this wait in time.
    while (!ring.wait_for_data(60s)) {
    }
    had_data = !ring.peek(1).empty();
    woke = true;
  });
  // Give the consumer the chance to fall asleep (not needed for correctness: if it has not slept
  // yet it sees the data on its own).
  std::this_thread::yield();
  push_one(ring, 1);
  ring.notify();
  consumer.join();
  const auto waited = std::chrono::steady_clock::now() - start;
  CHECK(woke);
  CHECK(had_data);
  CHECK(waited < 30s);
}
