#include "core/ptc/ptc_messages.hpp"

#include <fmt/format.h>

#include <algorithm>

namespace pandarcap::ptc {
namespace {

// Big-endian reads at fixed offsets of a payload already checked to be long enough.
class Reader {
 public:
  explicit Reader(std::span<const std::uint8_t> bytes) : b_(bytes) {}
  std::uint8_t u8(std::size_t at) const { return b_[at]; }
  std::uint16_t u16(std::size_t at) const {
    return static_cast<std::uint16_t>((b_[at] << 8) | b_[at + 1]);
  }
  std::uint32_t u32(std::size_t at) const {
    return (std::uint32_t{b_[at]} << 24) | (std::uint32_t{b_[at + 1]} << 16) |
           (std::uint32_t{b_[at + 2]} << 8) | std::uint32_t{b_[at + 3]};
  }
  std::int32_t i32(std::size_t at) const { return static_cast<std::int32_t>(u32(at)); }
  std::string text(std::size_t at, std::size_t size) const {
    std::string s;
    for (std::size_t i = at; i < at + size && b_[i] != 0; ++i) {
      const auto c = static_cast<char>(b_[i]);
      s.push_back(b_[i] >= 0x20 && b_[i] < 0x7F ? c : '?');
    }
    return s;
  }
  template <std::size_t N>
  std::array<std::uint8_t, N> bytes(std::size_t at) const {
    std::array<std::uint8_t, N> out{};
    std::copy_n(b_.begin() + static_cast<std::ptrdiff_t>(at), N, out.begin());
    return out;
  }

 private:
  std::span<const std::uint8_t> b_;
};

class Writer {
 public:
  explicit Writer(std::size_t size) : b_(size, 0) {}
  void u8(std::size_t at, std::uint8_t v) { b_[at] = v; }
  void u16(std::size_t at, std::uint16_t v) {
    b_[at] = static_cast<std::uint8_t>(v >> 8);
    b_[at + 1] = static_cast<std::uint8_t>(v);
  }
  void u32(std::size_t at, std::uint32_t v) {
    for (int i = 0; i < 4; ++i)
      b_[at + static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(v >> (24 - 8 * i));
  }
  void text(std::size_t at, std::size_t size, std::string_view s) {
    std::copy_n(s.begin(), std::min(size, s.size()), b_.begin() + static_cast<std::ptrdiff_t>(at));
  }
  template <std::size_t N>
  void bytes(std::size_t at, const std::array<std::uint8_t, N>& v) {
    std::copy(v.begin(), v.end(), b_.begin() + static_cast<std::ptrdiff_t>(at));
  }
  std::vector<std::uint8_t> take() { return std::move(b_); }

 private:
  std::vector<std::uint8_t> b_;
};

// The length check every payload gets first.
template <typename T>
bool long_enough(std::span<const std::uint8_t> payload, std::size_t layout, std::string_view what,
                 Parsed<T>& out) {
  if (payload.size() < layout) {
    out.error = fmt::format("{}: {} bytes, expected {}", what, payload.size(), layout);
    return false;
  }
  out.extra_bytes = payload.size() - layout;
  return true;
}

}  // namespace

std::string_view clock_source_name(std::uint8_t code) noexcept {
  switch (code) {
    case kClockSourceGps:
      return "gps";
    case kClockSourcePtp:
      return "ptp";
    default:
      return "unknown";
  }
}

std::string_view ptp_state_name(std::uint8_t code) noexcept {
  static constexpr std::string_view kNames[] = {"free_run", "tracking", "locked", "frozen"};
  return code < std::size(kNames) ? kNames[code] : "unknown";
}

Parsed<SensorInventory> parse_inventory(std::span<const std::uint8_t> payload) {
  Parsed<SensorInventory> out;
  if (!long_enough(payload, kInventoryBytes, "inventory", out)) return out;
  const Reader r(payload);
  SensorInventory v;
  v.serial = r.text(0, 18);
  v.manufacture_date = r.text(18, 16);
  v.mac = r.bytes<6>(34);
  v.software_version = r.text(40, 16);
  v.hardware_version = r.text(56, 16);
  v.control_firmware = r.text(72, 16);
  v.sensor_firmware = r.text(88, 16);
  v.zero_angle_offset = static_cast<std::int16_t>(r.u16(104));
  v.model = r.u8(106);
  v.motor_type = r.u8(107);
  v.lines = r.u8(108);
  out.value = std::move(v);
  return out;
}

Parsed<SensorSettings> parse_settings(std::span<const std::uint8_t> payload) {
  Parsed<SensorSettings> out;
  if (!long_enough(payload, kConfigBytes, "config", out)) return out;
  const Reader r(payload);
  SensorSettings v;
  v.ip = r.bytes<4>(0);
  v.netmask = r.bytes<4>(4);
  v.gateway = r.bytes<4>(8);
  v.destination_ip = r.bytes<4>(12);
  v.data_port = r.u16(16);
  v.gps_port = r.u16(18);
  v.spin_rate_rpm = r.u16(20);
  v.sync = r.u8(22);
  v.sync_angle = r.u16(23);
  v.start_angle = r.u16(25);
  v.stop_angle = r.u16(27);
  v.clock_source = r.u8(29);
  v.udp_sequence = r.u8(30);
  v.trigger_method = r.u8(31);
  v.return_mode = r.u8(32);
  v.standby_mode = r.u8(33);
  v.motor_status = r.u8(34);
  v.vlan_flag = r.u8(35);
  v.vlan_id = r.u16(36);
  v.clock_data_format = r.u8(38);
  v.noise_filtering = r.u8(39);
  v.reflectivity_mapping = r.u8(40);
  out.value = v;
  return out;
}

Parsed<SensorStatus> parse_status(std::span<const std::uint8_t> payload) {
  Parsed<SensorStatus> out;
  if (!long_enough(payload, kStatusBytes, "status", out)) return out;
  const Reader r(payload);
  SensorStatus v;
  v.uptime_s = r.u32(0);
  v.motor_rpm = r.u16(4);
  for (std::size_t i = 0; i < kTemperatureCount; ++i)
    v.temperature_centi_c[i] = r.i32(6 + 4 * i);
  v.gps_pps_locked = r.u8(38);
  v.gps_nmea_locked = r.u8(39);
  v.startup_count = r.i32(40);
  v.operation_minutes = r.i32(44);
  v.ptp_state = r.u8(48);
  out.value = v;
  return out;
}

Parsed<PtpDiagnostics> parse_ptp_status(std::span<const std::uint8_t> payload) {
  Parsed<PtpDiagnostics> out;
  if (!long_enough(payload, kPtpStatusBytes, "PTP status", out)) return out;
  const Reader r(payload);
  PtpDiagnostics v;
  v.master_offset_ns =
      static_cast<std::int64_t>((std::uint64_t{r.u32(0)} << 32) | std::uint64_t{r.u32(4)});
  v.state = r.i32(8);
  v.elapsed_ms = r.i32(12);
  out.value = v;
  return out;
}

std::vector<std::uint8_t> encode_ptp_status(const PtpDiagnostics& v) {
  Writer w(kPtpStatusBytes);
  const auto offset = static_cast<std::uint64_t>(v.master_offset_ns);
  w.u32(0, static_cast<std::uint32_t>(offset >> 32));
  w.u32(4, static_cast<std::uint32_t>(offset));
  w.u32(8, static_cast<std::uint32_t>(v.state));
  w.u32(12, static_cast<std::uint32_t>(v.elapsed_ms));
  return w.take();
}

std::vector<std::uint8_t> encode_inventory(const SensorInventory& v) {
  Writer w(kInventoryBytes);
  w.text(0, 18, v.serial);
  w.text(18, 16, v.manufacture_date);
  w.bytes(34, v.mac);
  w.text(40, 16, v.software_version);
  w.text(56, 16, v.hardware_version);
  w.text(72, 16, v.control_firmware);
  w.text(88, 16, v.sensor_firmware);
  w.u16(104, static_cast<std::uint16_t>(v.zero_angle_offset));
  w.u8(106, v.model);
  w.u8(107, v.motor_type);
  w.u8(108, v.lines);
  return w.take();
}

std::vector<std::uint8_t> encode_settings(const SensorSettings& v) {
  Writer w(kConfigBytes);
  w.bytes(0, v.ip);
  w.bytes(4, v.netmask);
  w.bytes(8, v.gateway);
  w.bytes(12, v.destination_ip);
  w.u16(16, v.data_port);
  w.u16(18, v.gps_port);
  w.u16(20, v.spin_rate_rpm);
  w.u8(22, v.sync);
  w.u16(23, v.sync_angle);
  w.u16(25, v.start_angle);
  w.u16(27, v.stop_angle);
  w.u8(29, v.clock_source);
  w.u8(30, v.udp_sequence);
  w.u8(31, v.trigger_method);
  w.u8(32, v.return_mode);
  w.u8(33, v.standby_mode);
  w.u8(34, v.motor_status);
  w.u8(35, v.vlan_flag);
  w.u16(36, v.vlan_id);
  w.u8(38, v.clock_data_format);
  w.u8(39, v.noise_filtering);
  w.u8(40, v.reflectivity_mapping);
  return w.take();
}

std::vector<std::uint8_t> encode_status(const SensorStatus& v) {
  Writer w(kStatusBytes);
  w.u32(0, v.uptime_s);
  w.u16(4, v.motor_rpm);
  for (std::size_t i = 0; i < kTemperatureCount; ++i)
    w.u32(6 + 4 * i, static_cast<std::uint32_t>(v.temperature_centi_c[i]));
  w.u8(38, v.gps_pps_locked);
  w.u8(39, v.gps_nmea_locked);
  w.u32(40, static_cast<std::uint32_t>(v.startup_count));
  w.u32(44, static_cast<std::uint32_t>(v.operation_minutes));
  w.u8(48, v.ptp_state);
  return w.take();
}

std::string mac_text(const std::array<std::uint8_t, 6>& m) {
  return fmt::format("{:02x}:{:02x}:{:02x}:{:02x}:{:02x}:{:02x}", m[0], m[1], m[2], m[3], m[4],
                     m[5]);
}

std::string ipv4_text(const std::array<std::uint8_t, 4>& a) {
  return fmt::format("{}.{}.{}.{}", a[0], a[1], a[2], a[3]);
}

}  // namespace pandarcap::ptc
