#include "core/decode/outlier_rule.hpp"

#include <cmath>
#include <cstdlib>
#include <cstring>

#include "core/sensors/sensor_model.hpp"
#include "core/sensors/timing.hpp"

namespace pandarcap {

int signed_step_cdeg(int a, int b) noexcept {
  int d = (a - b) % 36000;
  if (d < -18000) d += 36000;
  if (d >= 18000) d -= 36000;
  return d;
}

bool follows(const RotationPoint& last, const RotationPoint& next, Turning turning) noexcept {
  const int step = signed_step_cdeg(next.azimuth_cdeg, last.azimuth_cdeg);
  // A tail whose date went bad (zeroed, garbage) in a stream of good ones, or the reverse: not
  // the same clock. The rule then holds the packet, and places it at the time its azimuth gives
  // when the stream goes on as before.
  if (last.time_valid != next.time_valid) return false;
  const std::int64_t dt = next.t0_ns - last.t0_ns;
  if (!last.time_valid || last.time_stood || dt == 0 || last.rpm == 0) {
    return std::abs(step) <= 9000;
  }
  // At the speed of the last packet placed, or at the next one's where the stream's speed has
  // just changed (the stream decoder takes a tail speed only once two packets in a row say it).
  const auto at_speed = [&](std::uint16_t rpm) {
    // Half a revolution without packets is a gap whole revolutions may hide in (the assembler's
    // rule): never "follows".
    const double revolution_ns = 60e9 / rpm;
    if (std::abs(static_cast<double>(dt)) > revolution_ns / 2) return false;
    const double expected_cdeg =
        static_cast<int>(turning) * static_cast<double>(dt) / revolution_ns * kFullCircleCdeg;
    return std::abs(step - expected_cdeg) <= follow_tolerance_cdeg(expected_cdeg);
  };
  return at_speed(last.rpm) || (next.rpm != last.rpm && next.rpm != 0 && at_speed(next.rpm));
}

void HeldPackets::push(std::span<const std::uint8_t> payload, const AdmittedPacket& admitted,
                       std::optional<Turning> extends) noexcept {
  Entry& e = entries_[(head_ + count_) % kMaxHeldPackets];
  std::memcpy(e.bytes.data(), payload.data(), payload.size());
  e.size = payload.size();
  e.admitted = admitted;
  if (!extends) chain_start_ = count_;
  chain_turning_ = extends;
  ++count_;
}

void HeldPackets::pop_oldest() noexcept {
  head_ = (head_ + 1) % kMaxHeldPackets;
  --count_;
  ++forgotten_;
  if (chain_start_ > 0) --chain_start_;
}

}  // namespace pandarcap
