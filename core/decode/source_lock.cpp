#include "core/decode/source_lock.hpp"

#include "core/ipv4.hpp"
#include "core/sensors/packet.hpp"

namespace pandarcap {

void SourceLock::lock(std::uint32_t ip, std::uint16_t port, std::int64_t receive_ns) noexcept {
  sensor_ = pack_ipv4_source(ip, port);
  sensor_seen_ns_ = receive_ns;
}

SourceLock::Verdict SourceLock::judge(std::uint32_t ip, std::uint16_t port,
                                      std::span<const std::uint8_t> payload,
                                      std::int64_t receive_ns) noexcept {
  const std::uint64_t source = pack_ipv4_source(ip, port);
  if (sensor_ != 0 && source == sensor_) {
    sensor_seen_ns_ = receive_ns;
    return Verdict::kSensor;
  }
  // Not the sensor's (or no sensor yet): only a real packet matters.
  const bool packet = validate(payload) == RejectReason::kNone;
  // With sensor_ip, only that address can be (or become) the sensor, from any one port.
  const bool may_be_sensor = !sensor_ip_ || ip == *sensor_ip_;
  if (sensor_ == 0 && may_be_sensor) {
    if (packet) lock(ip, port, receive_ns);
    return Verdict::kSensor;
  }
  if (!packet) return Verdict::kForeign;
  if (sensor_ != 0 && may_be_sensor && receive_ns - sensor_seen_ns_ >= kRelockSilenceNs) {
    // The sensor has been silent, and another sends: it moved (a restart on a new port, a new
    // address), or it is gone.
    other_ = sensor_;
    ++changes_;
    lock(ip, port, receive_ns);
    return Verdict::kSensor;
  }
  other_ = source;
  return Verdict::kOtherSensor;
}

}  // namespace pandarcap
