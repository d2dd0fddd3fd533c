// SequenceTracker against its header contract: 32-bit UDP sequence numbers (+1 per packet,
// spec §1.3) classified modulo 2^32 into in-order, gaps, duplicates, late arrivals and resets.
#include <catch2/catch.hpp>
#include <cstdint>
#include <initializer_list>
#include <vector>

#include "core/decode/sequence_tracker.hpp"

using namespace pandarcap;
using Verdict = SequenceTracker::Verdict;

namespace {

// Feeds a sequence and returns the verdicts, one per number.
std::vector<Verdict> feed(SequenceTracker& tracker, std::initializer_list<std::uint32_t> numbers) {
  std::vector<Verdict> verdicts;
  for (std::uint32_t n : numbers)
    verdicts.push_back(tracker.observe(n));
  return verdicts;
}

// Every observed number gets exactly one verdict, and each verdict has its counter.
std::uint64_t classified(const SequenceStats& s) {
  return s.in_order + s.gaps + s.duplicates + s.reordered + s.resets;
}

}  // namespace

TEST_CASE("the first number is kFirst and counts nothing", "[sequence]") {
  for (std::uint32_t first : {0u, 1u, 10'636'899u, 0xFFFFFFFFu}) {
    SequenceTracker tracker;
    CHECK(tracker.observe(first) == Verdict::kFirst);
    const SequenceStats& s = tracker.stats();
    CHECK(classified(s) == 0);
    CHECK(s.lost == 0);
    // The next number after it is in order: the first one set the expectation.
    CHECK(tracker.observe(first + 1) == Verdict::kInOrder);
    CHECK(tracker.stats().in_order == 1);
  }
}

TEST_CASE("consecutive numbers are in order", "[sequence]") {
  SequenceTracker tracker;
  const std::uint32_t start = 10'636'899;  // the real 1266-byte capture's first sequence
  CHECK(tracker.observe(start) == Verdict::kFirst);
  for (std::uint32_t i = 1; i < 200; ++i)
    CHECK(tracker.observe(start + i) == Verdict::kInOrder);
  const SequenceStats& s = tracker.stats();
  CHECK(s.in_order == 199);
  CHECK(s.gaps == 0);
  CHECK(s.lost == 0);
  CHECK(s.duplicates == 0);
  CHECK(s.reordered == 0);
  CHECK(s.resets == 0);
}

TEST_CASE("a skip ahead is one gap event and counts the missing packets", "[sequence]") {
  SequenceTracker tracker;
  const auto v = feed(tracker, {100, 101, 105, 106, 107, 117});
  CHECK(v == std::vector<Verdict>{Verdict::kFirst, Verdict::kInOrder, Verdict::kGap,
                                  Verdict::kInOrder, Verdict::kInOrder, Verdict::kGap});
  const SequenceStats& s = tracker.stats();
  CHECK(s.gaps == 2);
  CHECK(s.lost == 3 + 9);  // 102..104 and 108..116
  CHECK(s.in_order == 3);
  CHECK(classified(s) == 5);
}

TEST_CASE("a gap of exactly kMaxGap is loss - one more is a reset", "[sequence]") {
  SECTION("kMaxGap ahead") {
    SequenceTracker tracker;
    tracker.observe(1000);
    CHECK(tracker.observe(1000 + SequenceTracker::kMaxGap) == Verdict::kGap);
    CHECK(tracker.stats().lost == SequenceTracker::kMaxGap - 1);
    CHECK(tracker.stats().resets == 0);
  }
  SECTION("kMaxGap + 1 ahead") {
    SequenceTracker tracker;
    tracker.observe(1000);
    CHECK(tracker.observe(1000 + SequenceTracker::kMaxGap + 1) == Verdict::kReset);
    CHECK(tracker.stats().lost == 0);
    CHECK(tracker.stats().gaps == 0);
    CHECK(tracker.stats().resets == 1);
    // Counting continues from the new number.
    CHECK(tracker.observe(1000 + SequenceTracker::kMaxGap + 2) == Verdict::kInOrder);
  }
}

TEST_CASE("the same number twice in a row is a duplicate", "[sequence]") {
  SequenceTracker tracker;
  const auto v = feed(tracker, {7, 8, 8, 8, 9});
  CHECK(v == std::vector<Verdict>{Verdict::kFirst, Verdict::kInOrder, Verdict::kDuplicate,
                                  Verdict::kDuplicate, Verdict::kInOrder});
  const SequenceStats& s = tracker.stats();
  CHECK(s.duplicates == 2);
  CHECK(s.in_order == 2);
  CHECK(s.lost == 0);
  CHECK(s.reordered == 0);
}

TEST_CASE("late packets inside the window are reordered and no longer lost", "[sequence]") {
  SequenceTracker tracker;
  // 3 and 4 are overtaken by 5: counted lost when 5 arrives, found again afterwards.
  CHECK(tracker.observe(1) == Verdict::kFirst);
  CHECK(tracker.observe(2) == Verdict::kInOrder);
  CHECK(tracker.observe(5) == Verdict::kGap);
  CHECK(tracker.stats().lost == 2);
  CHECK(tracker.observe(4) == Verdict::kReordered);
  CHECK(tracker.stats().lost == 1);
  CHECK(tracker.observe(3) == Verdict::kReordered);
  CHECK(tracker.stats().lost == 0);
  // The late ones did not move the expectation back: 6 follows 5.
  CHECK(tracker.observe(6) == Verdict::kInOrder);
  const SequenceStats& s = tracker.stats();
  CHECK(s.reordered == 2);
  CHECK(s.gaps == 1);
  CHECK(s.in_order == 2);
  CHECK(s.resets == 0);
}

TEST_CASE("two adjacent packets swapped: one gap, one late arrival, nothing lost", "[sequence]") {
  SequenceTracker tracker;
  const auto v = feed(tracker, {10, 11, 13, 12, 14, 15});
  CHECK(v == std::vector<Verdict>{Verdict::kFirst, Verdict::kInOrder, Verdict::kGap,
                                  Verdict::kReordered, Verdict::kInOrder, Verdict::kInOrder});
  CHECK(tracker.stats().lost == 0);
  CHECK(tracker.stats().reordered == 1);
}

TEST_CASE("a late packet repeated straight after itself is a duplicate", "[sequence]") {
  // Header: duplicates = "the same number as the previous packet"; lost = packets missing in the
  // gaps, late arrivals subtracted. Here 3 and 4 go missing, 3 arrives late (twice in a row), 4
  // never arrives: the second 3 is a duplicate and one packet (4) is still lost.
  SequenceTracker tracker;
  CHECK(tracker.observe(1) == Verdict::kFirst);
  CHECK(tracker.observe(2) == Verdict::kInOrder);
  CHECK(tracker.observe(5) == Verdict::kGap);
  CHECK(tracker.observe(3) == Verdict::kReordered);
  CHECK(tracker.observe(3) == Verdict::kDuplicate);
  const SequenceStats& s = tracker.stats();
  CHECK(s.duplicates == 1);
  CHECK(s.reordered == 1);
  CHECK(s.lost == 1);
}

TEST_CASE("the reorder window is kReorderWindow back - further back is a reset", "[sequence]") {
  const std::uint32_t high = 5000;
  SECTION("exactly kReorderWindow back") {
    SequenceTracker tracker;
    tracker.observe(high - 2000);
    CHECK(tracker.observe(high) == Verdict::kGap);  // 1999 lost
    CHECK(tracker.observe(high - SequenceTracker::kReorderWindow) == Verdict::kReordered);
    CHECK(tracker.stats().lost == 1998);
    CHECK(tracker.observe(high + 1) == Verdict::kInOrder);
  }
  SECTION("one further back") {
    SequenceTracker tracker;
    tracker.observe(high - 2000);
    CHECK(tracker.observe(high) == Verdict::kGap);
    CHECK(tracker.observe(high - SequenceTracker::kReorderWindow - 1) == Verdict::kReset);
    CHECK(tracker.stats().resets == 1);
    CHECK(tracker.stats().reordered == 0);
    CHECK(tracker.stats().lost == 1999);  // a reset neither adds nor forgives loss
    // The counter restarted at the reset's number.
    CHECK(tracker.observe(high - SequenceTracker::kReorderWindow) == Verdict::kInOrder);
  }
}

TEST_CASE("0xFFFFFFFF -> 0 is in order - gaps and late packets work across the wrap",
          "[sequence]") {
  SECTION("in order through the wrap") {
    SequenceTracker tracker;
    const auto v = feed(tracker, {0xFFFFFFFEu, 0xFFFFFFFFu, 0u, 1u, 2u});
    CHECK(v == std::vector<Verdict>{Verdict::kFirst, Verdict::kInOrder, Verdict::kInOrder,
                                    Verdict::kInOrder, Verdict::kInOrder});
    CHECK(tracker.stats().lost == 0);
    CHECK(tracker.stats().resets == 0);
  }
  SECTION("a gap spanning the wrap") {
    SequenceTracker tracker;
    const auto v = feed(tracker, {0xFFFFFFFDu, 1u});
    CHECK(v[1] == Verdict::kGap);
    CHECK(tracker.stats().lost == 3);  // FFFFFFFE, FFFFFFFF, 0
    SECTION("and the packets missing before the wrap arrive late") {
      CHECK(tracker.observe(0xFFFFFFFFu) == Verdict::kReordered);
      CHECK(tracker.observe(0u) == Verdict::kReordered);
      CHECK(tracker.stats().lost == 1);
      CHECK(tracker.observe(2u) == Verdict::kInOrder);
    }
  }
}

TEST_CASE("a sensor reboot restarts the counter: a reset, not billions lost", "[sequence]") {
  SECTION("back to 0 from far ahead") {
    SequenceTracker tracker;
    feed(tracker, {10'637'096u, 10'637'097u, 10'637'098u});
    CHECK(tracker.observe(0) == Verdict::kReset);
    CHECK(tracker.observe(1) == Verdict::kInOrder);
    CHECK(tracker.observe(2) == Verdict::kInOrder);
    CHECK(tracker.stats().lost == 0);
    CHECK(tracker.stats().resets == 1);
    CHECK(tracker.stats().in_order == 4);
  }
  SECTION("a huge jump forward") {
    SequenceTracker tracker;
    feed(tracker, {5u, 6u});
    CHECK(tracker.observe(0x80000000u) == Verdict::kReset);
    CHECK(tracker.observe(0x80000001u) == Verdict::kInOrder);
    CHECK(tracker.stats().lost == 0);
    CHECK(tracker.stats().gaps == 0);
  }
}

TEST_CASE("every observation after the first gets exactly one counted verdict", "[sequence]") {
  SequenceTracker tracker;
  // A deterministic mix of in-order runs, gaps, swaps, repeats and resets.
  std::vector<std::uint32_t> numbers;
  std::uint32_t n = 0xFFFFFF00u;
  std::uint64_t state = 12345;
  for (int i = 0; i < 5000; ++i) {
    state = state * 6364136223846793005ULL + 1442695040888963407ULL;
    const unsigned r = static_cast<unsigned>(state >> 33) % 100;
    if (r < 80) {
      numbers.push_back(++n);
    } else if (r < 88) {
      n += 1 + r % 7;
      numbers.push_back(n);
    } else if (r < 94) {
      numbers.push_back(n - r % 5);
    } else if (r < 99) {
      numbers.push_back(n);
    } else {
      n += 0x10000000u;
      numbers.push_back(n);
    }
  }
  std::uint64_t verdict_counts[6] = {};
  for (std::uint32_t x : numbers)
    ++verdict_counts[static_cast<int>(tracker.observe(x))];
  const SequenceStats& s = tracker.stats();
  CHECK(verdict_counts[static_cast<int>(Verdict::kFirst)] == 1);
  CHECK(verdict_counts[static_cast<int>(Verdict::kInOrder)] == s.in_order);
  CHECK(verdict_counts[static_cast<int>(Verdict::kGap)] == s.gaps);
  CHECK(verdict_counts[static_cast<int>(Verdict::kDuplicate)] == s.duplicates);
  CHECK(verdict_counts[static_cast<int>(Verdict::kReordered)] == s.reordered);
  CHECK(verdict_counts[static_cast<int>(Verdict::kReset)] == s.resets);
  CHECK(classified(s) == numbers.size() - 1);
}

TEST_CASE("an old number that already arrived is a duplicate, not a found loss", "[sequence]") {
  SequenceTracker tracker;
  const auto v = feed(tracker, {1, 2, 3, 5, 2, 4, 4});
  CHECK(v == std::vector<Verdict>{Verdict::kFirst, Verdict::kInOrder, Verdict::kInOrder,
                                  Verdict::kGap, Verdict::kDuplicate, Verdict::kReordered,
                                  Verdict::kDuplicate});
  const SequenceStats& s = tracker.stats();
  CHECK(s.lost == 0);  // 4 was missing and came; the repeats of 2 and 4 forgive nothing
  CHECK(s.duplicates == 2);
  CHECK(s.reordered == 1);
}

TEST_CASE("a number from before the first one is a duplicate, not a found loss", "[sequence]") {
  SequenceTracker tracker;
  const auto v = feed(tracker, {100, 101, 99});
  CHECK(v[2] == Verdict::kDuplicate);
  CHECK(tracker.stats().lost == 0);
}
