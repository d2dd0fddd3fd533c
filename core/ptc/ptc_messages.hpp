// The payloads of the PTC commands a capture daemon reads (../shared/spec/pandar40p-ptc.md §4),
// decoded from bytes and encoded back (the simulated sensor answers with these).
//
//   0x07 inventory  120 bytes  serial, versions, MAC, model
//   0x08 config      47 bytes  network, ports, spin rate, clock source (0 GPS, 1 PTP), modes
//   0x09 status      54 bytes  uptime, motor RPM, 8 temperatures (0.01 °C), GPS and PTP state
//   0x05 calibration CSV text  parsed by Calibration::parse, as a calibration file is
//
// A payload shorter than its layout is an error; a longer one parses, with the extra bytes
// reported (newer firmware appends fields), as nebula does. Strings are bounded by their field:
// a serial that fills its 18 bytes without a NUL is read as 18 characters; bytes after the
// first NUL are ignored; non-printable bytes become '?', so a hostile sensor cannot put control
// characters into the log or the health labels.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace pandarcap::ptc {

inline constexpr std::size_t kInventoryBytes = 120;
inline constexpr std::size_t kConfigBytes = 47;
inline constexpr std::size_t kStatusBytes = 54;

struct SensorInventory {
  std::string serial;            // 18 bytes
  std::string manufacture_date;  // 16
  std::array<std::uint8_t, 6> mac{};
  std::string software_version;  // 16
  std::string hardware_version;  // 16
  std::string control_firmware;  // 16
  std::string sensor_firmware;   // 16
  std::int16_t zero_angle_offset = 0;
  std::uint8_t model = 0;
  std::uint8_t motor_type = 0;
  std::uint8_t lines = 0;  // 40 on a Pandar40P
};

inline constexpr std::uint8_t kClockSourceGps = 0;
inline constexpr std::uint8_t kClockSourcePtp = 1;
std::string_view clock_source_name(std::uint8_t code) noexcept;  // "gps", "ptp", "unknown"

struct SensorSettings {
  std::array<std::uint8_t, 4> ip{}, netmask{}, gateway{}, destination_ip{};
  std::uint16_t data_port = 0;
  std::uint16_t gps_port = 0;
  std::uint16_t spin_rate_rpm = 0;
  std::uint8_t sync = 0;
  std::uint16_t sync_angle = 0;
  std::uint16_t start_angle = 0;
  std::uint16_t stop_angle = 0;
  std::uint8_t clock_source = 0;  // kClockSourceGps / kClockSourcePtp
  std::uint8_t udp_sequence = 0;  // 1: 1266-byte packets
  std::uint8_t trigger_method = 0;
  std::uint8_t return_mode = 0;  // the code the packets' tail carries
  std::uint8_t standby_mode = 0;
  std::uint8_t motor_status = 0;
  std::uint8_t vlan_flag = 0;
  std::uint16_t vlan_id = 0;
  std::uint8_t clock_data_format = 0;
  std::uint8_t noise_filtering = 0;
  std::uint8_t reflectivity_mapping = 0;
};

// The PTP clock status byte of 0x09.
enum class PtpState : std::uint8_t { kFreeRun = 0, kTracking = 1, kLocked = 2, kFrozen = 3 };
inline constexpr std::size_t kPtpStateCount = 4;
std::string_view ptp_state_name(std::uint8_t code) noexcept;  // "free_run", ... or "unknown"

inline constexpr std::size_t kTemperatureCount = 8;
// The temperatures' names, in their order in the status payload.
inline constexpr std::array<std::string_view, kTemperatureCount> kTemperatureNames = {
    "bottom_t1",    "bottom_t2", "laser_rt_l", "laser_rt_r",
    "receiver_rt2", "top_rt3",   "top_rt4",    "top_rt5"};

struct SensorStatus {
  std::uint32_t uptime_s = 0;
  std::uint16_t motor_rpm = 0;
  std::array<std::int32_t, kTemperatureCount> temperature_centi_c{};  // 0.01 °C
  std::uint8_t gps_pps_locked = 0;
  std::uint8_t gps_nmea_locked = 0;
  std::int32_t startup_count = 0;
  std::int32_t operation_minutes = 0;
  std::uint8_t ptp_state = 0;  // PtpState, or an unknown code as received
};

// 0x06 with query 0x01 ("PTP status"): 16 bytes. Whether a Pandar40P firmware answers it is
// unknown (spec §4); an "unsupported" return code is expected, and the status byte used instead.
inline constexpr std::size_t kPtpStatusBytes = 16;
inline constexpr std::uint8_t kPtpQueryStatus = 0x01;
struct PtpDiagnostics {
  std::int64_t master_offset_ns = 0;  // linuxptp's "offset from master", in nanoseconds
  std::int32_t state = 0;
  std::int32_t elapsed_ms = 0;
};

template <typename T>
struct Parsed {
  std::optional<T> value;
  std::string error;            // when !value: "status: 40 bytes, expected 54"
  std::size_t extra_bytes = 0;  // when value: bytes past the known layout (newer firmware)
};

Parsed<SensorInventory> parse_inventory(std::span<const std::uint8_t> payload);
Parsed<SensorSettings> parse_settings(std::span<const std::uint8_t> payload);
Parsed<SensorStatus> parse_status(std::span<const std::uint8_t> payload);
Parsed<PtpDiagnostics> parse_ptp_status(std::span<const std::uint8_t> payload);

// The layouts back to bytes (reserved bytes zero; strings cut to their field).
std::vector<std::uint8_t> encode_inventory(const SensorInventory& inventory);
std::vector<std::uint8_t> encode_settings(const SensorSettings& settings);
std::vector<std::uint8_t> encode_status(const SensorStatus& status);
std::vector<std::uint8_t> encode_ptp_status(const PtpDiagnostics& ptp);

// "aa:bb:cc:dd:ee:ff", "192.168.1.201".
std::string mac_text(const std::array<std::uint8_t, 6>& mac);
std::string ipv4_text(const std::array<std::uint8_t, 4>& address);

}  // namespace pandarcap::ptc
