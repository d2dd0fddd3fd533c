// The real capture's payloads as a sensor would send them, for as long as a test needs: the
// 1439 dual-return packets of pandar40p_nebula_dual_600rpm_1262B.pcap looped (its last azimuth
// joins its first within a degree), each with its tail time from a running sensor clock, 1/3600 s
// apart. For single return, two consecutive dual packets' last-return blocks make one packet (ten
// blocks 0.2° apart: a real single-return packet's geometry, real distances), 1/1800 s apart,
// with the return-mode byte of the mode asked for, each loop turned so it joins the last at a
// packet's step (the dual loop joins 0.15° short, as the capture's end meets its start).
// Optionally with the 4-byte UDP sequence.
//
// The faults the tests put into such a stream (set_time, shift_azimuth, ...) rewrite a packet's
// bytes as a sensor's or a network's glitch would.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include "core/sensors/packet.hpp"

namespace pandarcap::test {

class RetimedCapture {
 public:
  // The stream in `mode`; nothing when the capture is not there (test::real_capture's rules:
  // under CI=true the test fails instead).
  static std::optional<RetimedCapture> load(ReturnMode mode);

  // The first packet's time: 2024-03-01T12:00:00Z.
  static constexpr std::int64_t kStartUnixNs = 1'709'294'400'000'000'000;

  ReturnMode mode() const noexcept { return mode_; }
  // 1/3600 s (dual), 1/1800 s (single), in ns.
  std::int64_t period_ns() const noexcept { return period_ns_; }
  std::uint64_t packets_per_second() const noexcept { return per_second_; }
  // Packets the looped source holds before it repeats.
  std::size_t distinct() const noexcept { return bodies_.size(); }

  // Packet k's time: exactly k / rate seconds after the start.
  std::int64_t time_ns(std::uint64_t k) const noexcept {
    return kStartUnixNs +
           static_cast<std::int64_t>(k) * 1'000'000'000 / static_cast<std::int64_t>(per_second_);
  }
  // Packet k of the stream into `out`: its size (1262, or 1266 with a sequence).
  std::size_t packet(std::uint64_t k, std::span<std::uint8_t, kMaxPacketBytes> out,
                     std::optional<std::uint32_t> sequence = {}) const;

 private:
  ReturnMode mode_ = ReturnMode::kDual;
  std::int64_t period_ns_ = 0;
  std::uint64_t per_second_ = 0;
  std::vector<std::array<std::uint8_t, kPacketBytes>> bodies_;
  int seam_cdeg_ = 0;  // how far each loop is turned back where it joins the last (single return)
};

// Faults, on a packet's bytes (1262 or 1266).
// The tail's date and microseconds for `unix_ns`.
void set_time(std::span<std::uint8_t> packet, std::int64_t unix_ns);
// The date bytes of the second before, the microseconds kept: the sensor's date lagging a wrap.
void date_second_back(std::span<std::uint8_t> packet);
// Date and microseconds all zero; or bytes no clock writes (month 13, microseconds past 10^6).
void zero_time(std::span<std::uint8_t> packet);
void garbage_time(std::span<std::uint8_t> packet, std::uint32_t seed);
// Every block's azimuth moved by `cdeg` (mod 360°), or all set to `cdeg`.
void shift_azimuth(std::span<std::uint8_t> packet, int cdeg);
void set_azimuth(std::span<std::uint8_t> packet, int cdeg);
// The tail's motor speed.
void set_rpm(std::span<std::uint8_t> packet, std::uint16_t rpm);
std::uint16_t first_azimuth(std::span<const std::uint8_t> packet);

}  // namespace pandarcap::test
