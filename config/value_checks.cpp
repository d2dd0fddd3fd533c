#include "config/value_checks.hpp"

#include <arpa/inet.h>
#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <initializer_list>

#include "core/decode/decoder_target.hpp"
#include "core/ipv4.hpp"
#include "core/sensors/sensor_model_id.hpp"

namespace pandarcap::config_detail {
namespace {

std::optional<std::string> one_of(const std::string& s, std::initializer_list<const char*> names) {
  std::string list;
  for (const char* n : names) {
    if (s == n) return std::nullopt;
    list += list.empty() ? "" : ", ";
    list += n;
  }
  return fmt::format("\"{}\" is not one of {}", s, list);
}

// ROS 2 names: a topic is absolute ("/pandar/points"), a frame id is not; both are made of
// letters, digits, '_' and '/' separators, so ros2 bag play and tf accept them.
std::optional<std::string> ros_name(const std::string& s, bool absolute) {
  if (s.empty()) return "must not be empty";
  if (absolute && s.front() != '/') return "must start with '/' (a ROS 2 topic)";
  if (!absolute && s.front() == '/') return "must not start with '/' (a ROS 2 frame id)";
  if (s.back() == '/' || s.find("//") != std::string::npos) return "must not have empty parts";
  for (const char c : s) {
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '_' && c != '/') {
      return "may hold only letters, digits, '_' and '/'";
    }
  }
  return std::nullopt;
}

}  // namespace

std::optional<std::string> any_string(const std::string&) {
  return std::nullopt;
}

std::optional<std::string> non_empty(const std::string& s) {
  if (s.empty()) return "must not be empty";
  return std::nullopt;
}

std::optional<std::string> ipv4(const std::string& s) {
  if (!parse_ipv4(s)) return fmt::format("\"{}\" is not an IPv4 address (a.b.c.d)", s);
  return std::nullopt;
}

std::optional<std::string> ipv4_or_empty(const std::string& s) {
  if (s.empty()) return std::nullopt;
  return ipv4(s);
}

std::optional<std::string> multicast_or_empty(const std::string& s) {
  if (s.empty()) return std::nullopt;
  const auto a = parse_ipv4(s);
  if (!a) return ipv4(s);
  if ((ntohl(a->s_addr) >> 28) != 0xE) {
    return fmt::format("\"{}\" is not a multicast address (224.0.0.0/4)", s);
  }
  return std::nullopt;
}

// node_exporter's textfile collector reads only files named *.prom.
std::optional<std::string> prom_file_or_empty(const std::string& s) {
  if (s.empty()) return std::nullopt;
  if (s.size() < 6 || !s.ends_with(".prom") || s.ends_with("/.prom")) {
    return fmt::format(
        "\"{}\" must be a file name ending in .prom (node_exporter's textfile "
        "collector reads no other)",
        s);
  }
  return std::nullopt;
}

std::optional<std::string> sensor_model(const std::string& s) {
  if (s == "auto" || parse_sensor_model(s)) return std::nullopt;
  return fmt::format(
      "\"{}\" is not a sensor model: \"auto\", \"Pandar40P\", \"Pandar64\", \"PandarXT32\", "
      "\"PandarXT16\" or \"PandarQT128\" (any case)",
      s);
}

std::optional<std::string> receiver(const std::string& s) {
  return one_of(s, {"socket", "packet_ring"});
}

// A network interface's name as the kernel takes it (dev_valid_name): 1..15 bytes, not "." or
// "..", no '/', ':' or white space.
std::optional<std::string> interface_or_empty(const std::string& s) {
  if (s.empty()) return std::nullopt;
  const bool bad_char = std::any_of(s.begin(), s.end(), [](char c) {
    return c == '/' || c == ':' || std::isspace(static_cast<unsigned char>(c)) || c == '\0';
  });
  if (s.size() > 15 || s == "." || s == ".." || bad_char) {
    return fmt::format(
        "\"{}\" is not a network interface name (1 to 15 characters, no '/', ':' or spaces)", s);
  }
  return std::nullopt;
}

std::optional<std::string> return_mode(const std::string& s) {
  return one_of(s, {"any", "last", "strongest", "dual"});
}

std::optional<std::string> calibration_source(const std::string& s) {
  return one_of(s, {"auto", "sensor", "file", "nominal"});
}

std::optional<std::string> pcd_fields(const std::string& s) {
  return one_of(s, {"pcl", "pandarcap", "velodyne", "autoware"});
}

std::optional<std::string> axes(const std::string& s) {
  return one_of(s, {"hesai", "ros"});
}

std::optional<std::string> mcap_compression(const std::string& s) {
  return one_of(s, {"zstd", "lz4", "none"});
}

std::optional<std::string> pcap_compression(const std::string& s) {
  return one_of(s, {"none", "zstd"});
}

std::optional<std::string> pcd_compression(const std::string& s) {
  return one_of(s, {"none", "lzf"});
}

std::optional<std::string> topic(const std::string& s) {
  return ros_name(s, true);
}
std::optional<std::string> frame_id(const std::string& s) {
  return ros_name(s, false);
}

std::optional<std::string> log_level(const std::string& s) {
  return one_of(s, {"trace", "debug", "info", "warn", "error", "critical", "off"});
}

// Only the name is checked here: whether this CPU runs the target is checked at start-up, so a
// config is valid or not independently of the machine it is checked on.
std::optional<std::string> decoder_name(const std::string& s) {
  if (s == "auto" || decoder_target_from_string(s)) return std::nullopt;
  return "must be auto, scalar, sse4, avx2, avx512, neon, sve or sve2";
}

// The sensor name becomes a Prometheus label value and a JSON string; refuse the characters that
// would need escaping there so the name reads the same in every output.
std::optional<std::string> label(const std::string& s) {
  if (s.empty()) return "must not be empty";
  for (const char c : s) {
    if (c == '"' || c == '\\' || static_cast<unsigned char>(c) < 0x20) {
      return "must not contain quotes, backslashes or control characters";
    }
  }
  return std::nullopt;
}

std::optional<std::string> label_or_empty(const std::string& s) {
  return s.empty() ? std::nullopt : label(s);
}

std::optional<std::string> device_name(const std::string& s) {
  if (s.size() > 255) return "must be at most 255 bytes";
  for (const char c : s) {
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7F)
      return "must not contain control characters";
  }
  return std::nullopt;
}

std::string describe(const RealRange& r) {
  if (std::isinf(r.hi)) return fmt::format("{} {}", r.lo_open ? ">" : ">=", r.lo);
  return fmt::format("{}{}, {}{}", r.lo_open ? '(' : '[', r.lo, r.hi, r.hi_open ? ')' : ']');
}

bool in_range(double v, const RealRange& r) {
  if (!std::isfinite(v)) return false;
  if (r.lo_open ? v <= r.lo : v < r.lo) return false;
  if (r.hi_open ? v >= r.hi : v > r.hi) return false;
  return true;
}

}  // namespace pandarcap::config_detail
