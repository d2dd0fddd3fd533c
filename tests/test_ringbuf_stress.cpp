// Threaded stress of the SPSC rings: 10^7 counter values per run (2 * 10^6 under the sanitizers)
// must each arrive exactly once, in order and intact, across random power-of-two capacities
// (1..4096) and random batch sizes, with the two threads free and with both pinned to one core
// (where every full or empty ring forces a context switch). These run under ThreadSanitizer in CI
// (the tsan workflow), next to a negative control that proves TSan would flag a ring whose
// acquire/release were relaxed.
#include <catch2/catch.hpp>
#include <cstdint>
#include <cstdlib>
#include <optional>
#include <random>
#include <string>

#include "support/ringbuf_stress.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
using namespace pandarcap::test;

namespace {

// 10^7 by default; PANDARCAP_STRESS_ITEMS overrides it (e.g. for a quick local run). Under the
// sanitizers 2 * 10^6: ThreadSanitizer judges each access's ordering by happens-before, not by
// luck of the interleaving, so what it can find shows in far fewer items (its negative control
// reports the relaxed ring within 100 000), and each item costs it 5-10 times a release
// build's; the release job keeps the full count for the interleavings themselves.
std::uint64_t total_items() {
  if (const char* env = std::getenv("PANDARCAP_STRESS_ITEMS")) {
    return std::strtoull(env, nullptr, 10);
  }
  return kSlowBuild ? 2'000'000 : 10'000'000;
}

// Splits the total over `rounds` random capacities 2^0..2^12 and random batch limits.
template <typename Run>
void run_rounds(Run run, std::optional<int> pin_cpu, std::uint64_t seed) {
  constexpr int kRounds = 16;
  const std::uint64_t per_round = total_items() / kRounds;
  std::mt19937_64 rng(seed);
  std::uniform_int_distribution<int> log2_capacity(0, 12);
  std::uniform_int_distribution<std::size_t> max_batch(1, 64);
  std::uint64_t received = 0;
  for (int round = 0; round < kRounds; ++round) {
    StressPlan plan;
    // Always cover the extremes: capacity 1 and 4096.
    const int log2 = round == 0 ? 0 : round == 1 ? 12 : log2_capacity(rng);
    plan.capacity = std::size_t{1} << log2;
    plan.items = per_round;
    plan.max_producer_batch = max_batch(rng);
    plan.max_consumer_batch = max_batch(rng);
    plan.seed = rng();
    plan.pin_cpu = pin_cpu;
    INFO("round " << round << ": capacity " << plan.capacity << ", batches up to "
                  << plan.max_producer_batch << "/" << plan.max_consumer_batch);
    const StressOutcome outcome = run(plan);
    CHECK(outcome.received == plan.items);
    CHECK(outcome.mismatches == 0);
    received += outcome.received;
  }
  CHECK(received == per_round * kRounds);
}

}  // namespace

TEST_CASE("packet ring: every counter arrives once, in order, intact (threads free)",
          "[ringbuf][threads]") {
  run_rounds(stress_packet_ring, std::nullopt, 20261122);
}

TEST_CASE("packet ring: every counter arrives once, in order, intact (one core)",
          "[ringbuf][threads]") {
  run_rounds(stress_packet_ring, first_allowed_cpu(), 4242);
}

TEST_CASE("typed queue: every counter arrives once, in order, intact (threads free)",
          "[ringbuf][threads]") {
  run_rounds(stress_typed_queue, std::nullopt, 777);
}

TEST_CASE("typed queue: every counter arrives once, in order, intact (one core)",
          "[ringbuf][threads]") {
  run_rounds(stress_typed_queue, first_allowed_cpu(), 31337);
}
