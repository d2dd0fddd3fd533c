// Classifies the optional 32-bit UDP sequence numbers (+1 per packet) into in-order, gaps,
// duplicates, late (reordered) packets and resets (a sensor reboot restarts its counter: that is
// not 4 billion lost packets). Arithmetic is modulo 2^32, so the wrap from 0xFFFFFFFF to 0 is
// in order.
//
// The tracker remembers which of the last kReorderWindow numbers have arrived (a 256-byte
// bitmap), so a late packet is told apart from a repeat: only a number that was really missing
// is "reordered" and forgiven from `lost`; a number that already arrived is a duplicate, however
// far back it is inside the window.
//
// The packet's time, where the caller has one, settles what the numbers alone cannot. A sensor
// that restarts within kReorderWindow packets of the start (or of its last restart) sends
// numbers that have already arrived, or that look like a reordered loss: a copy carries the time
// of the packet it copies, as old as its number says; a restarted counter's packet is new. So a
// number behind the highest whose time is not that of its place (newer than the highest's, or
// far from what its place gives) is a reset. Likewise a jump ahead much larger than the packets
// the time says were sent (a counter that restarted near 2^32, or at a random number) is a reset,
// not a loss.
#pragma once

#include <array>
#include <cstdint>
#include <optional>

namespace pandarcap {

struct SequenceStats {
  std::uint64_t in_order = 0;
  std::uint64_t gaps = 0;        // events: the sequence skipped ahead
  std::uint64_t lost = 0;        // packets missing in those gaps (late arrivals subtracted)
  std::uint64_t duplicates = 0;  // a number that had already arrived
  std::uint64_t reordered = 0;   // a missing number arriving after a higher one (no longer lost)
  std::uint64_t resets = 0;      // jumps too large to be loss or reordering
};

// A packet's time and the sensor's packet period: how many packets the time says were sent.
struct SequenceClock {
  std::int64_t t0_ns = 0;
  std::int64_t period_ns = 0;
};

class SequenceTracker {
 public:
  // Skips ahead by more than this, or back by more than kReorderWindow, mean a reset.
  static constexpr std::uint32_t kMaxGap = 1u << 16;
  static constexpr std::uint32_t kReorderWindow = 1024;

  enum class Verdict { kFirst, kInOrder, kGap, kDuplicate, kReordered, kReset };
  // `clock`: the packet's time, when valid (see above); without it, the numbers alone.
  Verdict observe(std::uint32_t sequence, std::optional<SequenceClock> clock = {}) noexcept;

  const SequenceStats& stats() const noexcept { return stats_; }

 private:
  // One bit per number in [last_ - kReorderWindow, last_] (kReorderWindow + 1 numbers), indexed by
  // the number modulo kBits; kBits is the next power of two that holds them all.
  static constexpr std::uint32_t kBits = 2 * kReorderWindow;
  static_assert((kBits & (kBits - 1)) == 0, "bitmap index is a mask");

  bool arrived(std::uint32_t sequence) const noexcept;
  void mark(std::uint32_t sequence, bool arrived) noexcept;
  void advance_to(std::uint32_t sequence) noexcept;  // numbers skipped become missing
  Verdict reset(std::uint32_t sequence) noexcept;
  // Packets sent since the highest number's packet, by the clocks; nothing without both times.
  std::optional<std::int64_t> elapsed_packets(const std::optional<SequenceClock>& clock) const;

  bool started_ = false;
  std::uint32_t last_ = 0;  // highest sequence seen (the next expected is last_ + 1)
  std::optional<SequenceClock> last_clock_;  // that packet's time
  std::array<std::uint64_t, kBits / 64> arrived_{};
  SequenceStats stats_;
};

}  // namespace pandarcap
