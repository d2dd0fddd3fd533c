// What the model headers share: the tail's date with its year resolved (each model has its own
// year rule), and a spinning model's rates, which follow from its firing period alone.
//
// Every Hesai spinning model fires on a time base: one firing every kFiringPeriodNs whatever the
// motor's speed, a firing filling `returns` blocks (one per echo). So a packet of kBlocks blocks
// holds kBlocks / returns firings, the packet rate is fixed by the return mode, and the speed
// only sets how far each packet turns:
//
//   model        firing period   blocks   packets/s single (dual)   per revolution at 600 RPM
//   Pandar40P    55.56 µs        10       1800 (3600)               180 (360)
//   Pandar64     55.56 µs         6       3000 (6000)               300 (600)
//   PandarXT     50.00 µs         8       2500 (5000)               250 (500)
//   PandarQT128  111.11 µs        2       4500 (9000)               450 (900)
#pragma once

#include <cstdint>

namespace pandarcap {

// A packet's UTC date and time with the year resolved by its model's rule (the tail holds one
// byte, counted from 2000 or 1900 depending on the model). Binary fields, not BCD; not checked:
// a sensor without a clock sends odd dates, and the packet clock judges them.
struct PacketDateTime {
  std::uint16_t year = 0;  // e.g. 2017
  std::uint8_t month = 0;  // 1..12
  std::uint8_t day = 0;    // 1..31
  std::uint8_t hour = 0;
  std::uint8_t minute = 0;
  std::uint8_t second = 0;  // 0..59 (60: a leap second)
  friend bool operator==(const PacketDateTime&, const PacketDateTime&) = default;
};

// The rates of a model firing every FiringPeriodNs, Blocks blocks to a packet. `returns` is
// returns_per_firing() of the packet's mode (1, 2 or 3) and must divide Blocks.
template <std::int64_t FiringPeriodNs, int Blocks>
struct FiringRates {
  static constexpr std::int64_t kFiringPeriodNs = FiringPeriodNs;

  static constexpr int firings_per_packet(int returns) noexcept { return Blocks / returns; }
  static constexpr std::int64_t packet_period_ns(int returns) noexcept {
    return kFiringPeriodNs * firings_per_packet(returns);
  }
  static constexpr double packets_per_second(int returns) noexcept {
    return 1e9 / static_cast<double>(packet_period_ns(returns));
  }
  // 0 for a motor that does not turn.
  static constexpr double packets_per_revolution(int returns, double rpm) noexcept {
    return rpm > 0 ? packets_per_second(returns) * 60.0 / rpm : 0.0;
  }
  // How far the first block's azimuth advances from one packet to the next (0.01°).
  static constexpr double azimuth_step_per_packet_cdeg(int returns, double rpm) noexcept {
    return rpm / 60.0 * 36000.0 * static_cast<double>(packet_period_ns(returns)) * 1e-9;
  }
  // How far the azimuth advances from one firing to the next (0.01°): 20 for a 40P at 600 RPM.
  static constexpr double azimuth_step_per_firing_cdeg(double rpm) noexcept {
    return rpm / 60.0 * 36000.0 * static_cast<double>(kFiringPeriodNs) * 1e-9;
  }
};

}  // namespace pandarcap
