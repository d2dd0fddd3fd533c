// One sensor per daemon: which datagrams on the data port are the sensor's. The live receiver
// and the replay judge every datagram's source with it before the ring (daemon/source/).
//
//   - sensor_ip set: the sensor is that address (any port). A datagram from anywhere else is
//     foreign: counted and dropped, as before.
//   - no sensor_ip (the default): the first address that sends a valid Pandar packet is the
//     sensor's; until then every datagram goes on to the decoder (which rejects and counts what
//     is not a packet). After it, a datagram from another address is foreign. The sensor's port
//     may change (a sensor that restarted, a sender that opened a new socket): the address is
//     what is locked, its latest port what is shown. The lock moves to another address only
//     when the locked one has been silent for kRelockSilenceNs and the other sends valid
//     packets (a sensor that came back with a new address): counted as a source change.
//
// A valid Pandar packet (validate(): its length, ten block markers and azimuths, its return
// mode; a few compares) from an address that is not the sensor's is another sensor on the port:
// counted (other_sensor_packets) and its source kept, so the health can name both (two sensors
// sending to one port would otherwise be merged, or dropped unseen). Sources are IPv4 (the live
// socket is IPv4); a replayed IPv6 record is not judged by the lock.
//
// Pure and allocation-free: one per source thread, which publishes what the health needs
// through its atomics (daemon/pipeline_types.hpp, ReceiveCounters).
#pragma once

#include <cstdint>
#include <optional>
#include <span>

namespace pandarcap {

class SourceLock {
 public:
  static constexpr std::int64_t kRelockSilenceNs = 1'000'000'000;

  // `sensor_ip` in host byte order; none: lock onto the first sender.
  explicit SourceLock(std::optional<std::uint32_t> sensor_ip) noexcept : sensor_ip_(sensor_ip) {}

  enum class Verdict {
    kSensor,       // the sensor's (or, before any lock, anyone's): to the decoder
    kForeign,      // not the sensor's, and not a Pandar packet: dropped, counted foreign
    kOtherSensor,  // a valid Pandar packet from another source: dropped, counted foreign too
  };
  // `receive_ns`: when it arrived (the kernel's time, or the capture's record time).
  Verdict judge(std::uint32_t ip, std::uint16_t port, std::span<const std::uint8_t> payload,
                std::int64_t receive_ns) noexcept;

  // Whether a datagram from `ip` is the sensor's as things stand (before any lock: anyone's),
  // without judging it: for a look ahead of the judging (the packet ring's arrival times). A
  // relock that judging would make is not foreseen.
  bool is_sensor_address(std::uint32_t ip) const noexcept;

  // Packed sources (core/ipv4.hpp's pack_ipv4_source; 0: none yet).
  std::uint64_t sensor_source() const noexcept { return sensor_; }
  std::uint64_t other_source() const noexcept { return other_; }
  std::uint64_t source_changes() const noexcept { return changes_; }

 private:
  void lock(std::uint32_t ip, std::uint16_t port, std::int64_t receive_ns) noexcept;

  std::optional<std::uint32_t> sensor_ip_;
  std::uint64_t sensor_ = 0;
  std::uint64_t other_ = 0;
  std::uint64_t changes_ = 0;
  std::int64_t sensor_seen_ns_ = 0;  // the sensor's last datagram
};

}  // namespace pandarcap
