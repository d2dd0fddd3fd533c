// pandarcap-ctl: a Pandar40P's own answers over its TCP control protocol (PTC), for operators.
//
//   pandarcap-ctl 192.168.1.201 calibration > front.csv     the table calibration_file accepts
//   pandarcap-ctl 192.168.1.201 status --json               PTP/GPS lock, motor, temperatures
//
// It sends only the read commands (0x05, 0x07, 0x08, 0x09); nothing here changes a sensor.
// Exit status: 0 answered, 64 usage, 69 no answer (refused, timed out, connection cut),
// 76 protocol error (not a PTC server, an error return code, a payload that does not parse).
#include <fmt/format.h>

#include <cstdio>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>

#include "core/ipv4.hpp"
#include "daemon/cli_args.hpp"
#include "daemon/ptc/ptc_client.hpp"
#include "daemon/ptc/sensor_json.hpp"
#include "daemon/ptc/sensor_queries.hpp"

namespace {

using namespace pandarcap;

constexpr std::string_view kVersion = PANDARCAP_VERSION;

constexpr std::string_view kUsage =
    R"(Usage: pandarcap-ctl SENSOR_IP calibration|inventory|config|status [options]

Asks a Hesai Pandar40P over its TCP control protocol (PTC, port 9347), as pandarcapd does at
start-up (calibration_source) and while it runs (status_interval_seconds). Reads only: no
command that changes the sensor is ever sent.

Commands:
  calibration   the angle-correction table as CSV: save it and give it as calibration_file
  inventory     serial number, firmware and hardware versions, MAC address
  config        addresses, destination port, spin rate, clock source (GPS or PTP), modes
  status        uptime, motor speed, temperatures, GPS PPS/NMEA lock, PTP state

Options:
  --json             the answer as JSON
  --port N           the PTC port (default 9347)
  --timeout-ms N     to connect, then for the whole answer (default 2000)
  --version          print the version and exit
  -h, --help         this text

Exit status: 0 answered, 64 usage error, 69 no answer (connection refused, timed out, cut
short), 76 protocol error (not a PTC server, an error return code, a malformed answer).
)";

constexpr int kExitUsage = 64;
constexpr int kExitUnavailable = 69;
constexpr int kExitProtocol = 76;

int exit_status(const PtcError& error) {
  switch (error.kind) {
    case ptc::ErrorKind::kConnectFailed:
    case ptc::ErrorKind::kTimeout:
    case ptc::ErrorKind::kIncomplete:
      return kExitUnavailable;
    default:
      return kExitProtocol;
  }
}

template <typename T>
int report(const Fetched<T>& answer, bool json, void (*text)(const T&)) {
  if (!answer.value) {
    std::fprintf(stderr, "pandarcap-ctl: %s\n", answer.error->message.c_str());
    return exit_status(*answer.error);
  }
  if (answer.extra_bytes > 0) {
    std::fprintf(stderr, "pandarcap-ctl: note: %zu bytes more than the Pandar40P layout\n",
                 answer.extra_bytes);
  }
  if (json) {
    fmt::print("{}\n", to_json(*answer.value).dump(2));
  } else {
    text(*answer.value);
  }
  return 0;
}

void print_calibration(const Calibration& c) {
  fmt::print("{}", c.to_csv());
}

void print_inventory(const ptc::SensorInventory& i) {
  fmt::print(
      "serial            {}\nmanufactured      {}\nMAC               {}\nsoftware          {}\n"
      "hardware          {}\ncontrol firmware  {}\nsensor firmware   {}\nlines             {}\n",
      i.serial, i.manufacture_date, ptc::mac_text(i.mac), i.software_version, i.hardware_version,
      i.control_firmware, i.sensor_firmware, i.lines);
}

void print_settings(const ptc::SensorSettings& s) {
  fmt::print(
      "address           {} netmask {} gateway {}\ndestination       {}:{} (GPS {})\n"
      "spin rate         {} RPM\nclock source      {}\nUDP sequence      {}\nreturn mode       "
      "0x{:02X}\nFoV               {:.1f}..{:.1f} deg\n",
      ptc::ipv4_text(s.ip), ptc::ipv4_text(s.netmask), ptc::ipv4_text(s.gateway),
      ptc::ipv4_text(s.destination_ip), s.data_port, s.gps_port, s.spin_rate_rpm,
      ptc::clock_source_name(s.clock_source), s.udp_sequence != 0 ? "on" : "off", s.return_mode,
      s.start_angle / 10.0, s.stop_angle / 10.0);
}

void print_status(const ptc::SensorStatus& s) {
  fmt::print(
      "uptime            {} s\nmotor             {} RPM\nPTP               {}\n"
      "GPS PPS           {}\nGPS NMEA          {}\nstart-ups         {}\n"
      "operated          {} min\n",
      s.uptime_s, s.motor_rpm, ptc::ptp_state_name(s.ptp_state),
      s.gps_pps_locked == 1 ? "locked" : "not locked",
      s.gps_nmea_locked == 1 ? "locked" : "not locked", s.startup_count, s.operation_minutes);
  for (std::size_t i = 0; i < ptc::kTemperatureCount; ++i)
    fmt::print("temperature       {:<13} {:.2f} C\n", ptc::kTemperatureNames[i],
               s.temperature_centi_c[i] / 100.0);
}

}  // namespace

int main(int argc, char** argv) {
  CliArgs args(argc, argv, kUsage);
  std::string address, command;
  bool json = false;
  PtcClientOptions options;
  while (args.more()) {
    const std::string_view arg = args.next();
    if (arg == "--json") {
      json = true;
    } else if (arg == "--port") {
      options.port = static_cast<std::uint16_t>(args.integer(arg, 1, 65535));
    } else if (arg == "--timeout-ms") {
      options.timeout = std::chrono::milliseconds(args.integer(arg, 100, 60'000));
    } else if (arg.starts_with("-")) {
      args.unknown_option(arg);
    } else if (address.empty()) {
      address = std::string(arg);
    } else if (command.empty()) {
      command = std::string(arg);
    } else {
      args.usage_error(fmt::format("unexpected argument '{}'", arg));
    }
  }
  if (address.empty() || command.empty()) args.usage_error("needs SENSOR_IP and a command");
  if (!parse_ipv4(address)) args.usage_error(fmt::format("'{}' is not an IPv4 address", address));
  options.address = address;
  PtcClient client(options);
  if (command == "calibration") {
    return report(fetch_calibration(client), json, &print_calibration);
  }
  if (command == "inventory") return report(fetch_inventory(client), json, &print_inventory);
  if (command == "config") return report(fetch_settings(client), json, &print_settings);
  if (command == "status") return report(fetch_status(client), json, &print_status);
  args.usage_error(
      fmt::format("unknown command '{}' (calibration, inventory, config, status)", command));
  return kExitUsage;
}
