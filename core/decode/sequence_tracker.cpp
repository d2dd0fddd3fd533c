#include "core/decode/sequence_tracker.hpp"

#include <cstdlib>

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

std::optional<std::int64_t> SequenceTracker::elapsed_packets(
    const std::optional<SequenceClock>& clock) const {
  if (!clock || !last_clock_ || clock->period_ns <= 0) return std::nullopt;
  const std::int64_t dt = clock->t0_ns - last_clock_->t0_ns;
  // Rounded to the nearest packet (the sensor's clock is regular to a microsecond).
  const std::int64_t half = clock->period_ns / 2;
  return (dt >= 0 ? dt + half : dt - half) / clock->period_ns;
}

SequenceTracker::Verdict SequenceTracker::reset(std::uint32_t sequence) noexcept {
  ++stats_.resets;
  // Numbers before the new start were never expected: a stray old one is a duplicate.
  arrived_.fill(~std::uint64_t{0});
  last_ = sequence;
  return Verdict::kReset;
}

SequenceTracker::Verdict SequenceTracker::observe(std::uint32_t sequence,
                                                  std::optional<SequenceClock> clock) noexcept {
  if (!started_) {
    started_ = true;
    // Numbers before the first one were never expected: mark them arrived so that a stray old
    // packet is a duplicate rather than a found loss.
    arrived_.fill(~std::uint64_t{0});
    last_ = sequence;
    last_clock_ = clock;
    return Verdict::kFirst;
  }
  const std::uint32_t ahead = sequence - last_;  // modulo 2^32
  if (ahead == 1) {
    ++stats_.in_order;
    advance_to(sequence);
    last_clock_ = clock;
    return Verdict::kInOrder;
  }
  const std::optional<std::int64_t> elapsed = elapsed_packets(clock);
  if (ahead != 0 && ahead <= kMaxGap) {
    // Far more numbers skipped than the time says packets were sent: the counter jumped.
    if (elapsed && *elapsed >= 1 && ahead > *elapsed + 2 + *elapsed / 16) {
      last_clock_ = clock;
      return reset(sequence);
    }
    ++stats_.gaps;
    stats_.lost += ahead - 1;
    advance_to(sequence);
    last_clock_ = clock;
    return Verdict::kGap;
  }
  const std::uint32_t behind = last_ - sequence;  // 0 for a repeat of the highest
  if (behind <= kReorderWindow) {
    const bool seen = arrived(sequence);
    if (elapsed) {
      // Where the time puts it against where its number does (behind the highest by `behind`).
      const std::int64_t place = -static_cast<std::int64_t>(behind);
      const std::int64_t tolerance = 2 + static_cast<std::int64_t>(behind) / 16;
      // Newer than the highest: a packet sent after it, whatever its number. A repeat whose time
      // is not its place's is not a copy either.
      if (*elapsed >= 1 || (seen && std::abs(*elapsed - place) > tolerance)) {
        last_clock_ = clock;
        return reset(sequence);
      }
    }
    if (seen) {
      ++stats_.duplicates;
      return Verdict::kDuplicate;
    }
    // It was counted lost when the gap opened; it has arrived after all.
    mark(sequence, true);
    ++stats_.reordered;
    --stats_.lost;
    return Verdict::kReordered;
  }
  last_clock_ = clock;
  return reset(sequence);
}

}  // namespace pandarcap
