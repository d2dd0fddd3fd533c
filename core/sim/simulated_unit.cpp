#include "core/sim/simulated_unit.hpp"

#include <cmath>

namespace pandarcap {

Calibration simulated_unit_calibration(SensorModelId model) {
  Calibration calibration = Calibration::nominal(model);
  for (int c = 0; c < calibration.channel_count; ++c) {
    const auto i = static_cast<std::size_t>(c);
    // Two incommensurate sines: every channel a different, repeatable offset within bounds.
    calibration.elevation_deg[i] += 0.40 * std::sin(1.7 * c + 0.3);
    calibration.azimuth_offset_deg[i] += 0.20 * std::cos(2.3 * c + 1.1);
    // Kept to the three decimals of the CSV, so the served text parses back to these values.
    calibration.elevation_deg[i] = std::round(calibration.elevation_deg[i] * 1e3) / 1e3;
    calibration.azimuth_offset_deg[i] = std::round(calibration.azimuth_offset_deg[i] * 1e3) / 1e3;
  }
  calibration.source = "simulated unit";
  return calibration;
}

SimulatedUnit simulated_unit(int rpm, std::uint8_t return_mode_code, bool udp_sequence,
                             std::uint16_t data_port, SensorModelId model) {
  SimulatedUnit unit;
  unit.calibration = simulated_unit_calibration(model);

  ptc::SensorInventory& inv = unit.inventory;
  inv.serial = "PCSIM40P00000001";
  inv.manufacture_date = "2026-11-01";
  inv.mac = {0x02, 0x50, 0x43, 0x00, 0x00, 0x01};  // locally administered
  inv.software_version = "pandarcap-sim";
  inv.hardware_version = "sim-1";
  inv.control_firmware = "sim-ctl-1.0";
  inv.sensor_firmware = "sim-fw-1.0";
  inv.model = 0;
  inv.lines = static_cast<std::uint8_t>(unit.calibration.channel_count);

  ptc::SensorSettings& s = unit.settings;
  s.ip = {127, 0, 0, 1};
  s.netmask = {255, 0, 0, 0};
  s.destination_ip = {127, 0, 0, 1};
  s.data_port = data_port;
  s.gps_port = 10110;
  s.spin_rate_rpm = static_cast<std::uint16_t>(rpm);
  s.stop_angle = 3600;
  s.clock_source = ptc::kClockSourcePtp;
  s.udp_sequence = udp_sequence ? 1 : 0;
  s.return_mode = return_mode_code;
  return unit;
}

ptc::SensorStatus SimulatedUnit::status(std::uint32_t uptime_s) const {
  ptc::SensorStatus st;
  st.uptime_s = uptime_s;
  st.motor_rpm = settings.spin_rate_rpm;
  // Boards at 38..52 °C, as a unit warmed up indoors reads.
  static constexpr std::int32_t kTemperatures[ptc::kTemperatureCount] = {4012, 4105, 5120, 5087,
                                                                         4630, 3877, 3901, 3950};
  for (std::size_t i = 0; i < ptc::kTemperatureCount; ++i)
    st.temperature_centi_c[i] = kTemperatures[i];
  st.gps_pps_locked = 0;
  st.gps_nmea_locked = 0;
  st.startup_count = 42;
  st.operation_minutes = static_cast<std::int32_t>(1000 + uptime_s / 60);
  st.ptp_state = ptp_state;
  return st;
}

}  // namespace pandarcap
