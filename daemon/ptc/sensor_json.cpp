#include "daemon/ptc/sensor_json.hpp"

namespace pandarcap {

nlohmann::ordered_json to_json(const ptc::SensorInventory& i) {
  return {{"serial", i.serial},
          {"manufacture_date", i.manufacture_date},
          {"mac", ptc::mac_text(i.mac)},
          {"software_version", i.software_version},
          {"hardware_version", i.hardware_version},
          {"control_firmware", i.control_firmware},
          {"sensor_firmware", i.sensor_firmware},
          {"zero_angle_offset", i.zero_angle_offset},
          {"model", i.model},
          {"motor_type", i.motor_type},
          {"lines", i.lines}};
}

nlohmann::ordered_json to_json(const ptc::SensorSettings& s) {
  return {{"ip", ptc::ipv4_text(s.ip)},
          {"netmask", ptc::ipv4_text(s.netmask)},
          {"gateway", ptc::ipv4_text(s.gateway)},
          {"destination_ip", ptc::ipv4_text(s.destination_ip)},
          {"data_port", s.data_port},
          {"gps_port", s.gps_port},
          {"spin_rate_rpm", s.spin_rate_rpm},
          {"sync", s.sync},
          {"sync_angle", s.sync_angle},
          {"start_angle", s.start_angle},
          {"stop_angle", s.stop_angle},
          {"clock_source", ptc::clock_source_name(s.clock_source)},
          {"udp_sequence", s.udp_sequence != 0},
          {"trigger_method", s.trigger_method},
          {"return_mode", s.return_mode},
          {"standby_mode", s.standby_mode},
          {"motor_status", s.motor_status},
          {"vlan_flag", s.vlan_flag},
          {"vlan_id", s.vlan_id},
          {"clock_data_format", s.clock_data_format},
          {"noise_filtering", s.noise_filtering},
          {"reflectivity_mapping", s.reflectivity_mapping}};
}

nlohmann::ordered_json to_json(const ptc::SensorStatus& s) {
  nlohmann::ordered_json temperatures = nlohmann::ordered_json::object();
  for (std::size_t i = 0; i < ptc::kTemperatureCount; ++i)
    temperatures[std::string(ptc::kTemperatureNames[i])] = s.temperature_centi_c[i] / 100.0;
  return {{"uptime_seconds", s.uptime_s},
          {"motor_rpm", s.motor_rpm},
          {"temperatures_celsius", temperatures},
          {"gps_pps_locked", s.gps_pps_locked == 1},
          {"gps_nmea_locked", s.gps_nmea_locked == 1},
          {"startup_count", s.startup_count},
          {"operation_minutes", s.operation_minutes},
          {"ptp_state", ptc::ptp_state_name(s.ptp_state)},
          {"ptp_state_code", s.ptp_state}};
}

nlohmann::ordered_json to_json(const Calibration& c) {
  nlohmann::ordered_json channels = nlohmann::ordered_json::array();
  for (int ch = 0; ch < c.channel_count; ++ch) {
    channels.push_back({{"channel", ch + 1},
                        {"elevation_deg", c.elevation_deg[ch]},
                        {"azimuth_offset_deg", c.azimuth_offset_deg[ch]}});
  }
  return {{"source", c.source}, {"channels", channels}};
}

}  // namespace pandarcap
