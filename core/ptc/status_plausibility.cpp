#include "core/ptc/status_plausibility.hpp"

#include <fmt/format.h>

#include <iterator>

namespace pandarcap::ptc {

std::uint32_t implausible_fields(const SensorStatus& status) noexcept {
  std::uint32_t fields = 0;
  const auto mark = [&](bool implausible, std::uint32_t bit) {
    if (implausible) fields |= 1u << bit;
  };
  mark(status.uptime_s > kMaxPlausibleUptimeSeconds, kUptimeBit);
  mark(status.motor_rpm > kMaxPlausibleMotorRpm, kMotorBit);
  for (std::size_t i = 0; i < kTemperatureCount; ++i) {
    const std::int32_t t = status.temperature_centi_c[i];
    mark(t < kMinPlausibleCentiCelsius || t > kMaxPlausibleCentiCelsius,
         kTemperatureBit0 + static_cast<std::uint32_t>(i));
  }
  mark(status.gps_pps_locked > 1, kGpsPpsBit);
  mark(status.gps_nmea_locked > 1, kGpsNmeaBit);
  mark(status.ptp_state >= kPtpStateCount, kPtpStateBit);
  return fields;
}

void describe_implausible(const SensorStatus& status, std::uint32_t fields, std::string& out) {
  const auto add = [&]<typename... Args>(fmt::format_string<Args...> format, Args&&... args) {
    if (!out.empty() && out.back() != ' ') out += "; ";
    fmt::format_to(std::back_inserter(out), format, std::forward<Args>(args)...);
  };
  const auto has = [&](std::uint32_t bit) { return (fields >> bit & 1u) != 0; };
  if (has(kUptimeBit)) {
    add("uptime {:.0f} years (0..10)", status.uptime_s / (365.25 * 24 * 3600));
  }
  if (has(kMotorBit)) add("motor speed {} RPM (0..{})", status.motor_rpm, kMaxPlausibleMotorRpm);
  for (std::size_t i = 0; i < kTemperatureCount; ++i) {
    if (has(kTemperatureBit0 + static_cast<std::uint32_t>(i))) {
      add("temperature {} {:.2f} °C ({}..{})", kTemperatureNames[i],
          status.temperature_centi_c[i] / 100.0, kMinPlausibleCentiCelsius / 100,
          kMaxPlausibleCentiCelsius / 100);
    }
  }
  if (has(kGpsPpsBit)) add("GPS PPS lock byte {} (0 or 1)", status.gps_pps_locked);
  if (has(kGpsNmeaBit)) add("GPS NMEA lock byte {} (0 or 1)", status.gps_nmea_locked);
  if (has(kPtpStateBit)) add("PTP state {} (0..3)", status.ptp_state);
}

void append_field_name(std::uint32_t bit, std::string& out) {
  if (bit == kUptimeBit) {
    out += "uptime_seconds";
  } else if (bit == kMotorBit) {
    out += "motor_rpm";
  } else if (bit >= kTemperatureBit0 && bit < kTemperatureBit0 + kTemperatureCount) {
    out += "temperature_";
    out += kTemperatureNames[bit - kTemperatureBit0];
  } else if (bit == kGpsPpsBit) {
    out += "gps_pps_locked";
  } else if (bit == kGpsNmeaBit) {
    out += "gps_nmea_locked";
  } else if (bit == kPtpStateBit) {
    out += "ptp_state";
  } else {
    out += "unknown";
  }
}

}  // namespace pandarcap::ptc
