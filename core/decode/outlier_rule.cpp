#include "core/decode/outlier_rule.hpp"

#include <cmath>
#include <cstdlib>
#include <cstring>

namespace pandarcap {

int signed_step_cdeg(int a, int b) noexcept {
  int d = (a - b) % 36000;
  if (d < -18000) d += 36000;
  if (d >= 18000) d -= 36000;
  return d;
}

bool follows(const RotationPoint& last, const RotationPoint& next) noexcept {
  const int step = signed_step_cdeg(next.azimuth_cdeg, last.azimuth_cdeg);
  // A tail whose date went bad (zeroed, garbage) in a stream of good ones, or the reverse: not
  // the same clock. The rule then holds the packet, and places it at the time its azimuth gives
  // when the stream goes on as before.
  if (last.time_valid != next.time_valid) return false;
  const std::int64_t dt = next.t0_ns - last.t0_ns;
  if (!last.time_valid || dt == 0 || last.rpm == 0) return std::abs(step) <= 9000;
  // Half a revolution without packets is a gap whole revolutions may hide in (the assembler's
  // rule): never "follows".
  const double revolution_ns = 60e9 / last.rpm;
  if (std::abs(static_cast<double>(dt)) > revolution_ns / 2) return false;
  const double expected_cdeg = static_cast<double>(dt) / revolution_ns * 36000.0;
  return std::abs(step - expected_cdeg) <= 200.0 + 0.02 * std::abs(expected_cdeg);
}

void HeldPackets::push(std::span<const std::uint8_t> payload, const AdmittedPacket& admitted,
                       bool extends_chain) noexcept {
  Entry& e = entries_[(head_ + count_) % kMaxHeldPackets];
  std::memcpy(e.bytes.data(), payload.data(), payload.size());
  e.size = payload.size();
  e.admitted = admitted;
  if (!extends_chain) chain_start_ = count_;
  ++count_;
}

void HeldPackets::pop_oldest() noexcept {
  head_ = (head_ + 1) % kMaxHeldPackets;
  --count_;
  if (chain_start_ > 0) --chain_start_;
}

}  // namespace pandarcap
