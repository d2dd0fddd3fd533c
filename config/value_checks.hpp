// The checks of single configuration values: integer and real ranges, and a function per kind
// of string (an IPv4 address, a ROS 2 topic, a Prometheus label, one of a few names). Each
// names the problem in words an operator can act on ("must be auto, scalar, sse4, ..."), or
// returns nothing when the value is fine. The key table (config_keys.hpp) says which check each
// key gets. Internal to config/.
#pragma once

#include <cstdint>
#include <limits>
#include <optional>
#include <string>

namespace pandarcap::config_detail {

// Allowed integer values, inclusive.
struct IntRange {
  std::int64_t lo;
  std::int64_t hi;
};

// Allowed real values; either end may be open. Non-finite values are never allowed.
struct RealRange {
  double lo;
  bool lo_open;
  double hi;  // +infinity: no upper bound
  bool hi_open;
};

// A check on a string value: the problem, or nothing when the value is fine.
using StringCheck = std::optional<std::string> (*)(const std::string&);

inline constexpr double kNoUpperBound = std::numeric_limits<double>::infinity();

std::optional<std::string> any_string(const std::string& s);
std::optional<std::string> non_empty(const std::string& s);
std::optional<std::string> ipv4(const std::string& s);
std::optional<std::string> ipv4_or_empty(const std::string& s);
std::optional<std::string> multicast_or_empty(const std::string& s);
// node_exporter's textfile collector reads only files named *.prom.
std::optional<std::string> prom_file_or_empty(const std::string& s);
std::optional<std::string> return_mode(const std::string& s);
std::optional<std::string> sensor_model(const std::string& s);
std::optional<std::string> receiver(const std::string& s);
std::optional<std::string> interface_or_empty(const std::string& s);
std::optional<std::string> label_or_empty(const std::string& s);
std::optional<std::string> calibration_source(const std::string& s);
std::optional<std::string> pcd_fields(const std::string& s);
std::optional<std::string> axes(const std::string& s);
std::optional<std::string> mcap_compression(const std::string& s);
std::optional<std::string> pcap_compression(const std::string& s);
std::optional<std::string> pcd_compression(const std::string& s);
// ROS 2 names: a topic is absolute ("/pandar/points"), a frame id is not.
std::optional<std::string> topic(const std::string& s);
std::optional<std::string> frame_id(const std::string& s);
std::optional<std::string> log_level(const std::string& s);
// A decoder's name; whether this CPU runs it is checked at start-up.
std::optional<std::string> decoder_name(const std::string& s);
// A name that appears as a Prometheus label value and a JSON string as it is.
std::optional<std::string> label(const std::string& s);
// output.device_name: "" (the host name) or a name of at most 255 bytes without control
// characters (it goes into MCAP metadata and JSON as it is).
std::optional<std::string> device_name(const std::string& s);

// "[0, 360)", "> 0": a range as its message says it.
std::string describe(const RealRange& r);
// Finite and inside `r`.
bool in_range(double v, const RealRange& r);

}  // namespace pandarcap::config_detail
