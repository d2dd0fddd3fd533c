#include "sequence_tracker.hpp"

namespace pandarcap {

bool SequenceTracker::arrived(std::uint32_t sequence) const noexcept {
  const std::uint32_t bit = sequence & (kBits - 1);
  return (arrived_[bit / 64] >> (bit % 64)) & 1u;
}

void SequenceTracker::mark(std::uint32_t sequence, bool arrived) noexcept {
  const std::uint32_t bit = sequence & (kBits - 1);
  const std::uint64_t mask = std::uint64_t{1} << (bit % 64);
  arrived_[bit / 64] = arrived ? (arrived_[bit / 64] | mask) : (arrived_[bit / 64] & ~mask);
}

void SequenceTracker::advance_to(std::uint32_t sequence) noexcept {
  // Only the numbers still inside the window need their bit cleared; older ones can no longer
  // be looked up.
  const std::uint32_t ahead = sequence - last_;
  const std::uint32_t clear = ahead - 1 < kReorderWindow + 1 ? ahead - 1 : kReorderWindow + 1;
  for (std::uint32_t i = 0; i < clear; ++i)
    mark(sequence - 1 - i, false);
  mark(sequence, true);
  last_ = sequence;
}

SequenceTracker::Verdict SequenceTracker::observe(std::uint32_t sequence) noexcept {
  if (!started_) {
    started_ = true;
    // Numbers before the first one were never expected: mark them arrived so that a stray old
    // packet is a duplicate rather than a found loss.
    arrived_.fill(~std::uint64_t{0});
    last_ = sequence;
    return Verdict::kFirst;
  }
  const std::uint32_t ahead = sequence - last_;  // modulo 2^32
  if (ahead == 1) {
    ++stats_.in_order;
    advance_to(sequence);
    return Verdict::kInOrder;
  }
  if (ahead == 0) {
    ++stats_.duplicates;
    return Verdict::kDuplicate;
  }
  if (ahead <= kMaxGap) {
    ++stats_.gaps;
    stats_.lost += ahead - 1;
    advance_to(sequence);
    return Verdict::kGap;
  }
  const std::uint32_t behind = last_ - sequence;
  if (behind <= kReorderWindow) {
    if (arrived(sequence)) {
      ++stats_.duplicates;
      return Verdict::kDuplicate;
    }
    // It was counted lost when the gap opened; it has arrived after all.
    mark(sequence, true);
    ++stats_.reordered;
    --stats_.lost;
    return Verdict::kReordered;
  }
  ++stats_.resets;
  arrived_.fill(~std::uint64_t{0});
  last_ = sequence;
  return Verdict::kReset;
}

}  // namespace pandarcap
