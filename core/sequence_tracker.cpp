#include "sequence_tracker.hpp"

namespace pandarcap {

SequenceTracker::Verdict SequenceTracker::observe(std::uint32_t sequence) noexcept {
  if (!started_) {
    started_ = true;
    last_ = sequence;
    return Verdict::kFirst;
  }
  const std::uint32_t ahead = sequence - last_;  // modulo 2^32
  if (ahead == 1) {
    ++stats_.in_order;
    last_ = sequence;
    return Verdict::kInOrder;
  }
  if (ahead == 0) {
    ++stats_.duplicates;
    return Verdict::kDuplicate;
  }
  if (ahead <= kMaxGap) {
    ++stats_.gaps;
    stats_.lost += ahead - 1;
    last_ = sequence;
    return Verdict::kGap;
  }
  const std::uint32_t behind = last_ - sequence;
  if (behind <= kReorderWindow) {
    // It was counted lost when the gap opened; it has arrived after all.
    ++stats_.reordered;
    if (stats_.lost > 0) --stats_.lost;
    return Verdict::kReordered;
  }
  ++stats_.resets;
  last_ = sequence;
  return Verdict::kReset;
}

}  // namespace pandarcap
