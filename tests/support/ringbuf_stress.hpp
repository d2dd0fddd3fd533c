// The strict-sequence stress run shared by the ring tests and the ThreadSanitizer negative
// control: a producer thread writes a counter into every slot, a consumer thread checks that every
// value arrives exactly once and in order. Nothing here uses Catch2 (it is not thread-safe, and
// the negative control is its own small program); the caller checks the returned counts.
#pragma once

#include <pthread.h>
#include <sched.h>

#include <chrono>
#include <cstdint>
#include <cstring>
#include <optional>
#include <random>
#include <thread>

#include "daemon/packet_slot.hpp"
#include "ringbuf/spsc_queue.hpp"

namespace pandarcap::test {

struct StressOutcome {
  std::uint64_t received = 0;       // items the consumer took out
  std::uint64_t mismatches = 0;     // items that were not the next counter value, or were damaged
  std::uint64_t producer_full = 0;  // times the producer found the ring full (and yielded)
  std::uint64_t consumer_waits = 0;
};

// Pins the calling thread to `cpu`; false if the kernel refused.
inline bool pin_to_cpu(int cpu) {
  cpu_set_t set;
  CPU_ZERO(&set);
  CPU_SET(cpu, &set);
  return pthread_setaffinity_np(pthread_self(), sizeof(set), &set) == 0;
}

// The first CPU this process may run on.
inline int first_allowed_cpu() {
  cpu_set_t set;
  CPU_ZERO(&set);
  if (sched_getaffinity(0, sizeof(set), &set) != 0) return 0;
  for (int cpu = 0; cpu < CPU_SETSIZE; ++cpu) {
    if (CPU_ISSET(cpu, &set)) return cpu;
  }
  return 0;
}

struct StressPlan {
  std::size_t capacity = 1;
  std::uint64_t items = 0;
  std::size_t max_producer_batch = 1;
  std::size_t max_consumer_batch = 1;
  std::uint64_t seed = 1;
  std::optional<int> pin_cpu;  // both threads on this CPU, or free
};

// Producer writes counter i into slot i (payload, length, source port, time) through
// reserve/publish in random batch sizes; the consumer reads through peek/release in random batch
// sizes and checks every field. A full ring makes the producer yield and retry (the daemon would
// drop and count instead; here every item must arrive).
inline StressOutcome stress_packet_ring(const StressPlan& plan) {
  PacketRing ring(plan.capacity);
  StressOutcome outcome;
  std::thread producer([&] {
    if (plan.pin_cpu) pin_to_cpu(*plan.pin_cpu);
    std::mt19937_64 rng(plan.seed);
    std::uniform_int_distribution<std::size_t> batch(1, plan.max_producer_batch);
    std::uint64_t next = 0;
    while (next < plan.items) {
      auto slots = ring.reserve(batch(rng));
      if (slots.empty()) {
        ++outcome.producer_full;
        std::this_thread::yield();
        continue;
      }
      std::size_t n = 0;
      for (PacketSlot& slot : slots) {
        if (next == plan.items) break;
        std::memcpy(slot.payload, &next, sizeof next);
        const std::uint64_t inverted = ~next;
        std::memcpy(slot.payload + PacketSlot::kPayloadCapacity - sizeof inverted, &inverted,
                    sizeof inverted);
        slot.length = static_cast<std::uint32_t>(next % 1267);
        slot.truncated = (next & 1) != 0;
        slot.receive_time_ns = static_cast<std::int64_t>(next * 3);
        slot.source.v4.sin_port = static_cast<std::uint16_t>(next);
        ++next;
        ++n;
      }
      ring.publish(n);
      ring.notify();
    }
  });
  std::thread consumer([&] {
    if (plan.pin_cpu) pin_to_cpu(*plan.pin_cpu);
    std::mt19937_64 rng(plan.seed ^ 0x9e3779b97f4a7c15ULL);
    std::uniform_int_distribution<std::size_t> batch(1, plan.max_consumer_batch);
    std::uint64_t expected = 0;
    while (expected < plan.items) {
      auto slots = ring.peek(batch(rng));
      if (slots.empty()) {
        ++outcome.consumer_waits;
        ring.wait_for_data(std::chrono::milliseconds(10));
        continue;
      }
      for (const PacketSlot& slot : slots) {
        std::uint64_t value = 0;
        std::uint64_t inverted = 0;
        std::memcpy(&value, slot.payload, sizeof value);
        std::memcpy(&inverted, slot.payload + PacketSlot::kPayloadCapacity - sizeof inverted,
                    sizeof inverted);
        const bool intact = value == expected && inverted == ~expected &&
                            slot.length == expected % 1267 &&
                            slot.truncated == ((expected & 1) != 0) &&
                            slot.receive_time_ns == static_cast<std::int64_t>(expected * 3) &&
                            slot.source.v4.sin_port == static_cast<std::uint16_t>(expected);
        if (!intact) ++outcome.mismatches;
        ++expected;
      }
      outcome.received += slots.size();
      ring.release(slots.size());
    }
  });
  producer.join();
  consumer.join();
  return outcome;
}

// The same strict sequence through the typed queue, one element per push/pop, with a payload
// that would show a torn or stale element.
struct StressMessage {
  std::uint64_t sequence = 0;
  std::uint64_t square = 0;
  std::uint64_t inverted = 0;
};

inline StressOutcome stress_typed_queue(const StressPlan& plan) {
  ringbuf::SpscQueue<StressMessage> queue(plan.capacity);
  StressOutcome outcome;
  std::thread producer([&] {
    if (plan.pin_cpu) pin_to_cpu(*plan.pin_cpu);
    for (std::uint64_t i = 0; i < plan.items;) {
      if (queue.try_push(StressMessage{i, i * i, ~i})) {
        ++i;
        if ((i & 63) == 0) queue.notify();
      } else {
        ++outcome.producer_full;
        queue.notify();
        std::this_thread::yield();
      }
    }
    queue.notify();
  });
  std::thread consumer([&] {
    if (plan.pin_cpu) pin_to_cpu(*plan.pin_cpu);
    for (std::uint64_t expected = 0; expected < plan.items;) {
      StressMessage* m = queue.front();
      if (m == nullptr) {
        ++outcome.consumer_waits;
        queue.wait_for_data(std::chrono::milliseconds(10));
        continue;
      }
      if (m->sequence != expected || m->square != expected * expected || m->inverted != ~expected) {
        ++outcome.mismatches;
      }
      queue.pop();
      ++outcome.received;
      ++expected;
    }
  });
  producer.join();
  consumer.join();
  return outcome;
}

}  // namespace pandarcap::test
