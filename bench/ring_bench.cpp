#include "bench/ring_bench.hpp"

#include <fmt/format.h>
#include <time.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstring>
#include <functional>
#include <thread>
#include <vector>

#include "bench/mutex_queue.hpp"
#include "bench/thread_pinning.hpp"
#include "core/sensors/packet.hpp"
#include "core/sensors/timing.hpp"
#include "daemon/clocks.hpp"
#include "daemon/packet_slot.hpp"
#include "ringbuf/spsc_queue.hpp"

namespace pandarcap::bench {
namespace {

using Clock = std::chrono::steady_clock;
using ringbuf::SpscQueue;
using ringbuf::detail::cpu_relax;

constexpr std::size_t kBatches[] = {1, 8, 32};

struct Throughput {
  double items_per_s = 0;
  std::uint64_t errors = 0;  // items that arrived out of order (must be 0)
};

// Starts producer and consumer on their CPUs, releases them together, and times from the release
// to the consumer taking the last item.
template <typename Producer, typename Consumer>
Throughput timed_pair(const Placement& where, std::uint64_t items, Producer produce,
                      Consumer consume) {
  std::atomic<int> ready{0};
  std::atomic<bool> go{false};
  Clock::time_point end;
  std::uint64_t errors = 0;
  std::thread producer([&] {
    pin_this_thread(where.producer_cpu);
    ready.fetch_add(1);
    while (!go.load(std::memory_order_acquire))
      std::this_thread::yield();
    produce();
  });
  std::thread consumer([&] {
    pin_this_thread(where.consumer_cpu);
    ready.fetch_add(1);
    while (!go.load(std::memory_order_acquire))
      std::this_thread::yield();
    errors = consume();
    end = Clock::now();
  });
  while (ready.load() < 2)
    std::this_thread::yield();
  const Clock::time_point start = Clock::now();
  go.store(true, std::memory_order_release);
  producer.join();
  consumer.join();
  const double seconds = std::chrono::duration<double>(end - start).count();
  return {static_cast<double>(items) / seconds, errors};
}

// The packet ring as the daemon drives it: the producer reserves up to `batch` slots, writes a
// sequence number and length into each (where recvmmsg would write the datagram), publishes them
// with one store and notifies once per batch; the consumer peeks up to `batch`, checks the order
// and releases with one store.
Throughput packet_ring_throughput(const Placement& where, std::size_t capacity, std::size_t batch,
                                  std::uint64_t items) {
  PacketRing ring(capacity);
  return timed_pair(
      where, items,
      [&] {
        std::uint64_t next = 0;
        while (next < items) {
          auto slots = ring.reserve(std::min<std::uint64_t>(batch, items - next));
          if (slots.empty()) {
            cpu_relax();
            continue;
          }
          for (PacketSlot& slot : slots) {
            std::memcpy(slot.payload, &next, sizeof next);
            slot.length = static_cast<std::uint32_t>(kPacketBytes);
            ++next;
          }
          ring.publish(slots.size());
          ring.notify();
        }
      },
      [&] {
        std::uint64_t expected = 0;
        std::uint64_t errors = 0;
        while (expected < items) {
          auto slots = ring.peek(batch);
          if (slots.empty()) {
            cpu_relax();
            continue;
          }
          for (const PacketSlot& slot : slots) {
            std::uint64_t value = 0;
            std::memcpy(&value, slot.payload, sizeof value);
            errors += value != expected++;
          }
          ring.release(slots.size());
        }
        return errors;
      });
}

Throughput typed_queue_throughput(const Placement& where, std::size_t capacity,
                                  std::uint64_t items) {
  SpscQueue<std::uint64_t> queue(capacity);
  return timed_pair(
      where, items,
      [&] {
        for (std::uint64_t i = 0; i < items;) {
          if (queue.try_push(i)) {
            ++i;
          } else {
            cpu_relax();
          }
        }
      },
      [&] {
        std::uint64_t errors = 0;
        for (std::uint64_t expected = 0; expected < items;) {
          const std::uint64_t* value = queue.front();
          if (value == nullptr) {
            cpu_relax();
            continue;
          }
          errors += *value != expected++;
          queue.pop();
        }
        return errors;
      });
}

Throughput mutex_queue_throughput(const Placement& where, std::size_t capacity,
                                  std::uint64_t items) {
  MutexQueue<std::uint64_t> queue(capacity);
  return timed_pair(
      where, items,
      [&] {
        for (std::uint64_t i = 0; i < items; ++i)
          queue.push(i);
      },
      [&] {
        std::uint64_t errors = 0;
        for (std::uint64_t expected = 0; expected < items; ++expected) {
          errors += queue.pop() != expected;
        }
        return errors;
      });
}

// ---- Round trips: `batch` items there and back; the echo thread spins (ring) or waits on its
// condition variable (mutex). Reported as the median and 99th percentile of `rounds` trips.

struct Latency {
  double p50_ns = 0;
  double p99_ns = 0;
};

Latency summarise(std::vector<double>& samples) {
  std::sort(samples.begin(), samples.end());
  const auto at = [&](double q) {
    return samples[std::min(samples.size() - 1,
                            static_cast<std::size_t>(q * static_cast<double>(samples.size())))];
  };
  return {at(0.50), at(0.99)};
}

// Sends `count` slots through `ring` (looping at the wrap of the storage).
void send_slots(PacketRing& ring, std::size_t count, std::uint64_t value) {
  while (count > 0) {
    auto slots = ring.reserve(count);
    for (PacketSlot& slot : slots)
      std::memcpy(slot.payload, &value, sizeof value);
    ring.publish(slots.size());
    count -= slots.size();
    if (slots.empty()) cpu_relax();
  }
}

void receive_slots(PacketRing& ring, std::size_t count) {
  while (count > 0) {
    auto slots = ring.peek(count);
    ring.release(slots.size());
    count -= slots.size();
    if (slots.empty()) cpu_relax();
  }
}

template <typename Ping, typename Echo>
Latency timed_round_trips(const Placement& where, std::uint64_t rounds, Ping ping, Echo echo) {
  std::vector<double> samples;
  samples.reserve(rounds);
  std::thread echoer([&] {
    pin_this_thread(where.consumer_cpu);
    echo();
  });
  std::thread pinger([&] {
    pin_this_thread(where.producer_cpu);
    for (std::uint64_t r = 0; r < rounds; ++r) {
      const Clock::time_point t0 = Clock::now();
      ping(r);
      samples.push_back(std::chrono::duration<double, std::nano>(Clock::now() - t0).count());
    }
  });
  pinger.join();
  echoer.join();
  return summarise(samples);
}

Latency packet_ring_round_trip(const Placement& where, std::size_t capacity, std::size_t batch,
                               std::uint64_t rounds) {
  PacketRing there(capacity);
  PacketRing back(capacity);
  return timed_round_trips(
      where, rounds,
      [&](std::uint64_t r) {
        send_slots(there, batch, r);
        receive_slots(back, batch);
      },
      [&] {
        for (std::uint64_t r = 0; r < rounds; ++r) {
          receive_slots(there, batch);
          send_slots(back, batch, r);
        }
      });
}

Latency typed_queue_round_trip(const Placement& where, std::size_t capacity, std::uint64_t rounds) {
  SpscQueue<std::uint64_t> there(capacity);
  SpscQueue<std::uint64_t> back(capacity);
  const auto move_one = [](SpscQueue<std::uint64_t>& from, SpscQueue<std::uint64_t>& to) {
    std::uint64_t value = 0;
    while (!from.try_pop(value))
      cpu_relax();
    while (!to.try_push(value))
      cpu_relax();
  };
  return timed_round_trips(
      where, rounds,
      [&](std::uint64_t r) {
        while (!there.try_push(r))
          cpu_relax();
        std::uint64_t value = 0;
        while (!back.try_pop(value))
          cpu_relax();
      },
      [&] {
        for (std::uint64_t r = 0; r < rounds; ++r)
          move_one(there, back);
      });
}

Latency mutex_queue_round_trip(const Placement& where, std::size_t capacity, std::uint64_t rounds) {
  MutexQueue<std::uint64_t> there(capacity);
  MutexQueue<std::uint64_t> back(capacity);
  return timed_round_trips(
      where, rounds,
      [&](std::uint64_t r) {
        there.push(r);
        back.pop();
      },
      [&] {
        for (std::uint64_t r = 0; r < rounds; ++r)
          back.push(there.pop());
      });
}

// ---- Idle CPU: the producer publishes one packet per sensor packet period (dual return at
// 600 RPM, the highest rate of a 10 Hz sensor) and notifies; the consumer waits in
// wait_for_data() as the decode worker does. Reports the consumer thread's CPU time over wall
// time.

nlohmann::ordered_json idle_consumer_cpu(const Placement& where, std::size_t capacity,
                                         double seconds) {
  const std::int64_t period_ns = packet_period_ns(ReturnMode::kDual);
  const auto packets = static_cast<std::uint64_t>(seconds * 1e9 / static_cast<double>(period_ns));
  PacketRing ring(capacity);
  std::atomic<bool> stop{false};
  std::uint64_t received = 0;
  double consumer_cpu = 0;
  double wall = 0;
  std::thread consumer([&] {
    pin_this_thread(where.consumer_cpu);
    const double cpu0 = thread_cpu_seconds();
    const Clock::time_point t0 = Clock::now();
    while (!stop.load(std::memory_order_relaxed)) {
      if (!ring.wait_for_data(std::chrono::milliseconds(100))) continue;
      auto slots = ring.peek(32);
      received += slots.size();
      ring.release(slots.size());
    }
    // Drain what is left after the stop flag.
    for (auto slots = ring.peek(32); !slots.empty(); slots = ring.peek(32)) {
      received += slots.size();
      ring.release(slots.size());
    }
    consumer_cpu = thread_cpu_seconds() - cpu0;
    wall = std::chrono::duration<double>(Clock::now() - t0).count();
  });
  std::thread producer([&] {
    pin_this_thread(where.producer_cpu);
    timespec next{};
    clock_gettime(CLOCK_MONOTONIC, &next);
    for (std::uint64_t i = 0; i < packets; ++i) {
      next.tv_nsec += period_ns;
      while (next.tv_nsec >= 1'000'000'000) {
        next.tv_nsec -= 1'000'000'000;
        ++next.tv_sec;
      }
      // Stands in for the receive thread blocking in recvmmsg until the next datagram.
      clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, nullptr);
      auto slots = ring.reserve(1);
      if (slots.empty()) continue;
      std::memcpy(slots[0].payload, &i, sizeof i);
      ring.publish(1);
      ring.notify();
    }
    stop.store(true, std::memory_order_relaxed);
    ring.notify();
  });
  producer.join();
  consumer.join();
  return {{"rate_packets_per_s", 1e9 / static_cast<double>(period_ns)},
          {"seconds", wall},
          {"packets_sent", packets},
          {"packets_received", received},
          {"consumer_cpu_percent", 100.0 * consumer_cpu / wall}};
}

template <typename Measure>
auto median_of(int repeat, Measure measure) {
  std::vector<decltype(measure())> runs;
  for (int i = 0; i < repeat; ++i)
    runs.push_back(measure());
  std::sort(runs.begin(), runs.end(),
            [](const auto& a, const auto& b) { return a.items_per_s < b.items_per_s; });
  return runs[runs.size() / 2];
}

Latency median_latency(int repeat, const std::function<Latency()>& measure) {
  std::vector<Latency> runs;
  for (int i = 0; i < repeat; ++i)
    runs.push_back(measure());
  std::sort(runs.begin(), runs.end(),
            [](const Latency& a, const Latency& b) { return a.p50_ns < b.p50_ns; });
  return runs[runs.size() / 2];
}

nlohmann::ordered_json to_json(const Latency& latency) {
  return {{"p50", latency.p50_ns}, {"p99", latency.p99_ns}};
}

}  // namespace

nlohmann::ordered_json run_ring_bench(const RingBenchOptions& options) {
  const Placement where = choose_placement();
  nlohmann::ordered_json report;
  report["benchmark"] = "ring";
  report["threads"] = where.describe();
  report["capacity"] = options.capacity;
  report["repeat"] = options.repeat;
  report["items"] = {{"ring", options.ring_items}, {"mutex", options.mutex_items}};
  std::uint64_t errors = 0;

  const Throughput mutex = median_of(options.repeat, [&] {
    return mutex_queue_throughput(where, options.capacity, options.mutex_items);
  });
  errors += mutex.errors;
  report["mutex_queue_items_per_s"] = mutex.items_per_s;

  nlohmann::ordered_json per_batch = nlohmann::ordered_json::object();
  nlohmann::ordered_json ratio_per_batch = nlohmann::ordered_json::object();
  for (std::size_t batch : kBatches) {
    const Throughput ring = median_of(options.repeat, [&] {
      return packet_ring_throughput(where, options.capacity, batch, options.ring_items);
    });
    errors += ring.errors;
    per_batch[std::to_string(batch)] = ring.items_per_s;
    ratio_per_batch[std::to_string(batch)] = ring.items_per_s / mutex.items_per_s;
  }
  report["packet_ring_items_per_s"] = per_batch;

  const Throughput typed = median_of(options.repeat, [&] {
    return typed_queue_throughput(where, options.capacity, options.ring_items);
  });
  errors += typed.errors;
  report["typed_queue_items_per_s"] = typed.items_per_s;

  // The headline ratio is the goal's: the packet ring at batch 32 against the mutex queue.
  report["ratio_vs_mutex"] = ratio_per_batch["32"];
  report["ratio_vs_mutex_per_batch"] = ratio_per_batch;
  report["typed_queue_ratio_vs_mutex"] = typed.items_per_s / mutex.items_per_s;

  nlohmann::ordered_json round_trip;
  for (std::size_t batch : kBatches) {
    round_trip["packet_ring"][std::to_string(batch)] = to_json(median_latency(options.repeat, [&] {
      return packet_ring_round_trip(where, options.capacity, batch, options.round_trips);
    }));
  }
  round_trip["typed_queue"] = to_json(median_latency(options.repeat, [&] {
    return typed_queue_round_trip(where, options.capacity, options.round_trips);
  }));
  round_trip["mutex_queue"] = to_json(median_latency(options.repeat, [&] {
    return mutex_queue_round_trip(where, options.capacity, options.round_trips / 10);
  }));
  report["round_trip_ns"] = round_trip;

  report["idle"] = idle_consumer_cpu(where, options.capacity, options.idle_seconds);

  report["order_errors"] = errors;
  report["goals"] = {
      {"ratio_vs_mutex_at_batch_32_min", 10},
      {"typed_queue_items_per_s_min", 1e8},
      {"ratio_met", report["ratio_vs_mutex"].get<double>() >= 10},
      {"typed_queue_met", typed.items_per_s >= 1e8},
  };
  return report;
}

void print_ring_report(const nlohmann::ordered_json& r) {
  fmt::print("ring benchmark: {}, capacity {}, median of {}\n", r["threads"].get<std::string>(),
             r["capacity"].get<std::size_t>(), r["repeat"].get<int>());
  const double mutex = r["mutex_queue_items_per_s"];
  fmt::print("  {:<28} {:>10.2f} M items/s\n", "mutex + condvar queue", mutex / 1e6);
  for (const auto& [batch, rate] : r["packet_ring_items_per_s"].items()) {
    fmt::print("  {:<28} {:>10.2f} M items/s  {:>6.1f}x mutex\n", "packet ring, batch " + batch,
               rate.get<double>() / 1e6, rate.get<double>() / mutex);
  }
  const double typed = r["typed_queue_items_per_s"];
  fmt::print("  {:<28} {:>10.2f} M items/s  {:>6.1f}x mutex\n", "typed queue", typed / 1e6,
             typed / mutex);
  fmt::print("round trip (ns, p50 / p99):\n");
  for (const auto& [batch, lat] : r["round_trip_ns"]["packet_ring"].items()) {
    fmt::print("  {:<28} {:>8.0f} / {:.0f}\n", "packet ring, batch " + batch,
               lat["p50"].get<double>(), lat["p99"].get<double>());
  }
  for (const char* name : {"typed_queue", "mutex_queue"}) {
    const auto& lat = r["round_trip_ns"][name];
    fmt::print("  {:<28} {:>8.0f} / {:.0f}\n", name, lat["p50"].get<double>(),
               lat["p99"].get<double>());
  }
  const auto& idle = r["idle"];
  fmt::print("idle consumer at {:.0f} packets/s: {:.2f}% of a core ({} of {} packets)\n",
             idle["rate_packets_per_s"].get<double>(), idle["consumer_cpu_percent"].get<double>(),
             idle["packets_received"].get<std::uint64_t>(),
             idle["packets_sent"].get<std::uint64_t>());
  fmt::print("order errors: {}\n", r["order_errors"].get<std::uint64_t>());
}

}  // namespace pandarcap::bench
