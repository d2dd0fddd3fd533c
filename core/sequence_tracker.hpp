// Classifies the optional 32-bit UDP sequence numbers (+1 per packet) into in-order, gaps,
// duplicates, late (reordered) packets and resets (a sensor reboot restarts its counter: that is
// not 4 billion lost packets). Arithmetic is modulo 2^32, so the wrap from 0xFFFFFFFF to 0 is
// in order.
#pragma once

#include <cstdint>

namespace pandarcap {

struct SequenceStats {
  std::uint64_t in_order = 0;
  std::uint64_t gaps = 0;        // events: the sequence skipped ahead
  std::uint64_t lost = 0;        // packets missing in those gaps (late arrivals subtracted)
  std::uint64_t duplicates = 0;  // the same number as the previous packet
  std::uint64_t reordered = 0;   // arrived after a higher number (counted missing, now found)
  std::uint64_t resets = 0;      // jumps too large to be loss or reordering
};

class SequenceTracker {
 public:
  // Skips ahead by more than this, or back by more than kReorderWindow, mean a reset.
  static constexpr std::uint32_t kMaxGap = 1u << 16;
  static constexpr std::uint32_t kReorderWindow = 1024;

  enum class Verdict { kFirst, kInOrder, kGap, kDuplicate, kReordered, kReset };
  Verdict observe(std::uint32_t sequence) noexcept;

  const SequenceStats& stats() const noexcept { return stats_; }

 private:
  bool started_ = false;
  std::uint32_t last_ = 0;  // highest sequence seen (the next expected is last_ + 1)
  SequenceStats stats_;
};

}  // namespace pandarcap
