// Which fields of a sensor's status (PTC 0x09) are physically possible. A status is what a
// device on the network says; a garbage answer (a firmware bug, another device on the port, a
// corrupted reply that still has the right length) must not be published as fact. Each field has
// the range a Pandar40P can report; what falls outside is left out of the health, counted, and
// makes the state degraded naming the field (core/health/health_policy.cpp).
//
// The ranges, and why:
//   uptime          0 .. 10 years: a sensor up longer than that has not been seen; 117 years
//                   (a uint32 of garbage) has not been possible.
//   motor speed     0 .. 1300 RPM: 0 stopped (standby), 600 or 1200 turning, a margin for
//                   spin-up overshoot.
//   temperatures    -60 .. +150 °C: the data sheet's ambient range is -20 .. +65 °C; boards run
//                   hotter, and no electronics survive past 150.
//   GPS locks       0 or 1 (the spec's only values).
//   PTP state       0 .. 3 (free run, tracking, locked, frozen).
#pragma once

#include <cstdint>
#include <string>

#include "core/ptc/ptc_messages.hpp"

namespace pandarcap::ptc {

inline constexpr std::uint32_t kMaxPlausibleUptimeSeconds = 10u * 366 * 24 * 3600;
inline constexpr std::uint16_t kMaxPlausibleMotorRpm = 1300;
inline constexpr std::int32_t kMinPlausibleCentiCelsius = -60 * 100;
inline constexpr std::int32_t kMaxPlausibleCentiCelsius = 150 * 100;

// One bit per field: bit kUptimeBit, kMotorBit, kTemperatureBit0 + i for temperature i, ...
inline constexpr std::uint32_t kUptimeBit = 0;
inline constexpr std::uint32_t kMotorBit = 1;
inline constexpr std::uint32_t kTemperatureBit0 = 2;
inline constexpr std::uint32_t kGpsPpsBit = kTemperatureBit0 + kTemperatureCount;
inline constexpr std::uint32_t kGpsNmeaBit = kGpsPpsBit + 1;
inline constexpr std::uint32_t kPtpStateBit = kGpsNmeaBit + 1;

// The fields of `status` outside their range, as bits (0: all plausible).
std::uint32_t implausible_fields(const SensorStatus& status) noexcept;

// "motor speed 53029 RPM (0..1300); temperature bottom_t1 -171234.56 °C (-60..150)" for the
// fields in `fields`, appended to `out` (nothing for 0).
void describe_implausible(const SensorStatus& status, std::uint32_t fields, std::string& out);

// Appends the field's name as the health record says it ("uptime_seconds", "motor_rpm",
// "temperature_bottom_t1", "gps_pps_locked", "gps_nmea_locked", "ptp_state"): plain ASCII.
void append_field_name(std::uint32_t bit, std::string& out);

}  // namespace pandarcap::ptc
