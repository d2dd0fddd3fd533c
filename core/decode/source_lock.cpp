#include "core/decode/source_lock.hpp"

#include "core/ipv4.hpp"
#include "core/sensors/packet.hpp"

namespace pandarcap {

void SourceLock::lock(std::uint32_t ip, std::uint16_t port, std::int64_t receive_ns) noexcept {
  sensor_ = pack_ipv4_source(ip, port);
  sensor_seen_ns_ = receive_ns;
}

bool SourceLock::is_sensor_address(std::uint32_t ip) const noexcept {
  if (sensor_ip_) return ip == *sensor_ip_;
  return sensor_ == 0 || ip == packed_ipv4(sensor_);
}

SourceLock::Verdict SourceLock::judge(std::uint32_t ip, std::uint16_t port,
                                      std::span<const std::uint8_t> payload,
                                      std::int64_t receive_ns) noexcept {
  const bool locked = sensor_ != 0 || sensor_ip_.has_value();
  const std::uint32_t sensor_ip = sensor_ip_ ? *sensor_ip_ : packed_ipv4(sensor_);
  if (locked && ip == sensor_ip) {
    lock(ip, port, receive_ns);
    return Verdict::kSensor;
  }
  // Not the sensor's (or no sensor yet): only a real packet matters.
  const bool packet = validate(payload) == RejectReason::kNone;
  if (!locked) {
    if (packet) lock(ip, port, receive_ns);
    return Verdict::kSensor;
  }
  if (!packet) return Verdict::kForeign;
  if (!sensor_ip_ && receive_ns - sensor_seen_ns_ >= kRelockSilenceNs) {
    // The sensor has been silent, and another sends: it moved (or it is gone).
    other_ = sensor_;
    ++changes_;
    lock(ip, port, receive_ns);
    return Verdict::kSensor;
  }
  other_ = pack_ipv4_source(ip, port);
  return Verdict::kOtherSensor;
}

}  // namespace pandarcap
