// The TOML configuration, read with toml++.
//
// One list of keys (for_each_key) drives everything: reading the file, the range checks, the
// unknown-key check and printing. Adding a key means adding one line there, so the file format,
// the checks and `--print-config` cannot drift apart.
#include "config/config_loader.hpp"

#include <arpa/inet.h>
#include <fmt/format.h>
#include <toml++/toml.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <limits>
#include <map>
#include <optional>
#include <set>
#include <span>
#include <variant>
#include <vector>

#include "config/suggest.hpp"
#include "core/decoder_target.hpp"
#include "core/ipv4.hpp"
#include "core/text_file.hpp"

namespace pandarcap {
namespace {

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

constexpr double kNoUpperBound = std::numeric_limits<double>::infinity();

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

std::optional<std::string> one_of(const std::string& s, std::initializer_list<const char*> names) {
  std::string list;
  for (const char* n : names) {
    if (s == n) return std::nullopt;
    list += list.empty() ? "" : ", ";
    list += n;
  }
  return fmt::format("\"{}\" is not one of {}", s, list);
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
  return one_of(s, {"zstd", "none"});
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
std::optional<std::string> topic(const std::string& s) {
  return ros_name(s, true);
}
std::optional<std::string> frame_id(const std::string& s) {
  return ros_name(s, false);
}

std::optional<std::string> log_level(const std::string& s) {
  return one_of(s, {"trace", "debug", "info", "warn", "error", "critical", "off"});
}

// The sensor name becomes a Prometheus label value and a JSON string; refuse the characters that
// would need escaping there so the name reads the same in every output.
// Only the name is checked here: whether this CPU runs the target is checked at start-up, so a
// config is valid or not independently of the machine it is checked on.
std::optional<std::string> decoder_name(const std::string& s) {
  if (s == "auto" || decoder_target_from_string(s)) return std::nullopt;
  return "must be auto, scalar, sse4, avx2, avx512, neon, sve or sve2";
}

std::optional<std::string> label(const std::string& s) {
  if (s.empty()) return "must not be empty";
  for (const char c : s) {
    if (c == '"' || c == '\\' || static_cast<unsigned char>(c) < 0x20) {
      return "must not contain quotes, backslashes or control characters";
    }
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

// Calls `v` once per configuration key, in the order of config/pandarcap.toml:
//   v(table, key, member, check)
// where `check` is an IntRange, a RealRange, a StringCheck, or nothing for booleans.
// Table "" is the document's top level.
template <typename Config, typename Visitor>
void for_each_key(Config& c, Visitor&& v) {
  constexpr std::int64_t kU32 = std::numeric_limits<std::uint32_t>::max();
  constexpr std::int64_t kI64 = std::numeric_limits<std::int64_t>::max();
  constexpr std::int64_t kMaxCpu = 1023;  // CPU_SETSIZE - 1
  v("", "log_level", c.log_level, &log_level);
  v("", "decoder", c.decoder, &decoder_name);

  auto& s = c.sensor;
  v("sensor", "sensor_ip", s.sensor_ip, &ipv4_or_empty);
  v("sensor", "host_ip", s.host_ip, &ipv4);
  v("sensor", "multicast_ip", s.multicast_ip, &multicast_or_empty);
  v("sensor", "multicast_interface_ip", s.multicast_interface_ip, &ipv4_or_empty);
  v("sensor", "data_port", s.data_port, IntRange{1, 65535});
  v("sensor", "udp_socket_receive_buffer_size_bytes", s.udp_socket_receive_buffer_size_bytes,
    IntRange{0, std::numeric_limits<std::int32_t>::max()});
  v("sensor", "return_mode", s.return_mode, &return_mode);
  v("sensor", "rotation_speed", s.rotation_speed, IntRange{600, 1200});
  v("sensor", "cut_angle", s.cut_angle, RealRange{0.0, false, 360.0, true});
  v("sensor", "min_range", s.min_range, RealRange{0.0, false, kNoUpperBound, false});
  v("sensor", "max_range", s.max_range, RealRange{0.0, true, kNoUpperBound, false});
  v("sensor", "dual_return_distance_threshold", s.dual_return_distance_threshold,
    RealRange{0.0, false, kNoUpperBound, false});
  v("sensor", "calibration_file", s.calibration_file, &any_string);
  v("sensor", "firing_time_correction", s.firing_time_correction, std::monostate{});
  v("sensor", "calibration_source", s.calibration_source, &calibration_source);
  v("sensor", "frame", s.frame, &axes);
  v("sensor", "ptc_port", s.ptc_port, IntRange{1, 65535});
  v("sensor", "ptc_timeout_ms", s.ptc_timeout_ms, IntRange{100, 60'000});
  v("sensor", "status_interval_seconds", s.status_interval_seconds,
    RealRange{0.0, false, 3600.0, false});

  v("ring", "slots", c.ring.slots, IntRange{64, 1 << 20});
  v("ring", "receive_batch", c.ring.receive_batch, IntRange{1, 1024});

  v("arenas", "count", c.arenas.count, IntRange{2, 64});
  v("arenas", "points_per_frame", c.arenas.points_per_frame, IntRange{1000, 10'000'000});
  v("arenas", "packets_per_frame", c.arenas.packets_per_frame, IntRange{1, 65536});

  auto& o = c.output;
  v("output", "directory", o.directory, &non_empty);
  v("output", "frames", o.frames, std::monostate{});
  v("output", "pcd_fields", o.pcd_fields, &pcd_fields);
  v("output", "frame_decimation", o.frame_decimation, IntRange{1, kU32});
  v("output", "frames_min_fraction", o.frames_min_fraction, RealRange{0.0, false, 1.0, false});
  v("output", "frames_max_files", o.frames_max_files, IntRange{0, kI64});
  v("output", "frames_max_bytes", o.frames_max_bytes, IntRange{0, kI64});
  v("output", "pcap", o.pcap, std::monostate{});
  v("output", "pcap_rotate_bytes", o.pcap_rotate_bytes, IntRange{0, kI64});
  v("output", "pcap_rotate_seconds", o.pcap_rotate_seconds, IntRange{0, kU32});
  v("output", "pcap_max_files", o.pcap_max_files, IntRange{0, kI64});
  v("output", "pcap_max_bytes", o.pcap_max_bytes, IntRange{0, kI64});
  v("output", "mcap", o.mcap, std::monostate{});
  v("output", "mcap_packets", o.mcap_packets, std::monostate{});
  v("output", "mcap_compression", o.mcap_compression, &mcap_compression);
  v("output", "mcap_compression_level", o.mcap_compression_level, IntRange{-7, 19});
  v("output", "mcap_chunk_bytes", o.mcap_chunk_bytes, IntRange{64 * 1024, 256 << 20});
  v("output", "mcap_rotate_bytes", o.mcap_rotate_bytes, IntRange{0, kI64});
  v("output", "mcap_rotate_seconds", o.mcap_rotate_seconds, IntRange{0, kU32});
  v("output", "mcap_max_files", o.mcap_max_files, IntRange{0, kI64});
  v("output", "mcap_max_bytes", o.mcap_max_bytes, IntRange{0, kI64});
  v("output", "mcap_frame_id", o.mcap_frame_id, &frame_id);
  v("output", "mcap_points_topic", o.mcap_points_topic, &topic);
  v("output", "mcap_health_topic", o.mcap_health_topic, &topic);
  v("output", "mcap_packets_topic", o.mcap_packets_topic, &topic);

  auto& h = c.health;
  v("health", "sensor_name", h.sensor_name, &label);
  v("health", "no_data_timeout_seconds", h.no_data_timeout_seconds,
    RealRange{0.0, true, 86400.0, false});
  v("health", "max_sensor_clock_offset_seconds", h.max_sensor_clock_offset_seconds,
    RealRange{0.0, false, kNoUpperBound, true});
  v("health", "prometheus", h.prometheus, std::monostate{});
  v("health", "jsonl", h.jsonl, std::monostate{});
  v("health", "jsonl_rotate_bytes", h.jsonl_rotate_bytes, IntRange{0, kI64});
  v("health", "directory", h.directory, &any_string);
  v("health", "prometheus_file", h.prometheus_file, &prom_file_or_empty);

  auto& t = c.threads;
  v("threads", "receive_cpu", t.receive_cpu, IntRange{-1, kMaxCpu});
  v("threads", "decode_cpu", t.decode_cpu, IntRange{-1, kMaxCpu});
  v("threads", "writer_cpu", t.writer_cpu, IntRange{-1, kMaxCpu});
  v("threads", "receive_priority", t.receive_priority, IntRange{0, 99});
  v("threads", "decode_priority", t.decode_priority, IntRange{0, 99});
  v("threads", "writer_priority", t.writer_priority, IntRange{0, 99});
  v("threads", "lock_memory", t.lock_memory, std::monostate{});

  v("latency", "budget_ms", c.latency.budget_ms, IntRange{0, 1000});
}

std::string dotted(std::string_view table, std::string_view key) {
  return table.empty() ? std::string(key) : fmt::format("{}.{}", table, key);
}

// Where each key was found, so value checks can point at the line.
using Positions = std::map<std::string, toml::source_position, std::less<>>;

// Builds "where: key: message" with `where` the key's position if known, else the source name.
class Reporter {
 public:
  Reporter(const std::string& source_name, const Positions* positions)
      : source_(source_name), positions_(positions) {}

  [[noreturn]] void fail(std::string_view key, const std::string& message) const {
    if (positions_ != nullptr) {
      if (auto it = positions_->find(key); it != positions_->end()) {
        fail_at(it->second, key, message);
      }
    }
    throw ConfigError(fmt::format("{}: {}: {}", source_, key, message));
  }

  [[noreturn]] void fail_at(const toml::source_position& at, std::string_view key,
                            const std::string& message) const {
    throw ConfigError(fmt::format("{}:{}:{}: {}: {}", source_, at.line, at.column, key, message));
  }

 private:
  const std::string& source_;
  const Positions* positions_;
};

// Range checks of single values (the file reader has already checked the types).
struct ValueChecker {
  const Reporter& report;

  void operator()(std::string_view table, std::string_view key, const std::string& value,
                  StringCheck check) const {
    if (auto problem = check(value)) report.fail(dotted(table, key), *problem);
  }
  void operator()(std::string_view, std::string_view, bool, std::monostate) const {}
  template <typename Int>
  void operator()(std::string_view table, std::string_view key, Int value, IntRange r) const {
    const auto v = static_cast<long double>(value);
    if (v < static_cast<long double>(r.lo) || v > static_cast<long double>(r.hi)) {
      report.fail(dotted(table, key),
                  fmt::format("{} is out of range ({}..{})", value, r.lo, r.hi));
    }
  }
  void operator()(std::string_view table, std::string_view key, double value,
                  const RealRange& r) const {
    if (!in_range(value, r)) {
      report.fail(dotted(table, key), fmt::format("{} is out of range ({}{})", value, describe(r),
                                                  std::isfinite(value) ? "" : ", finite"));
    }
  }
};

// One problem found in a file: where (for the order they are reported in) and its whole text.
struct Problem {
  toml::source_position at;
  std::string text;
};

// Runs `check`, which reports through a throwing Reporter, and keeps what it throws: a file's
// problems are reported all at once, in the order of the file, not one per run.
template <typename Check>
void collect(std::vector<Problem>& problems, const Positions& positions, std::string_view key,
             Check&& check) {
  try {
    check();
  } catch (const ConfigError& error) {
    const auto it = positions.find(key);
    problems.push_back(
        Problem{it != positions.end() ? it->second : toml::source_position{}, error.what()});
  }
}

// The checks between keys, each one reported against the key that must change.
void check_between_keys(
    const DaemonConfig& c, const Reporter& report,
    const std::function<void(std::string_view, const std::function<void()>&)>& each) {
  const auto& s = c.sensor;
  each("sensor.rotation_speed", [&] {
    if (s.rotation_speed != 600 && s.rotation_speed != 1200) {
      report.fail(
          "sensor.rotation_speed",
          fmt::format("{} RPM is not a Pandar40P motor speed (600 or 1200)", s.rotation_speed));
    }
  });
  each("sensor.max_range", [&] {
    if (!(s.max_range > s.min_range)) {
      report.fail("sensor.max_range", fmt::format("{} must be greater than sensor.min_range ({})",
                                                  s.max_range, s.min_range));
    }
  });
  each("sensor.calibration_source", [&] {
    if (s.calibration_source == "file" && s.calibration_file.empty()) {
      report.fail("sensor.calibration_source",
                  "\"file\" needs sensor.calibration_file (the CSV to decode with)");
    }
  });
  each("sensor.status_interval_seconds", [&] {
    if (s.status_interval_seconds > 0 && s.status_interval_seconds < 0.1) {
      report.fail(
          "sensor.status_interval_seconds",
          fmt::format("{} is too often (0 = off, or at least 0.1)", s.status_interval_seconds));
    }
  });
  const auto slots = c.ring.slots;
  each("ring.slots", [&] {
    if ((slots & (slots - 1)) != 0) {
      report.fail("ring.slots", fmt::format("{} is not a power of two", slots));
    }
  });
  each("ring.receive_batch", [&] {
    if (c.ring.receive_batch > slots) {
      report.fail("ring.receive_batch",
                  fmt::format("{} is more than ring.slots ({})", c.ring.receive_batch, slots));
    }
  });
}

// Every value check (each key's range, then the checks between keys), all problems kept.
void check_values(const DaemonConfig& c, const Reporter& report, const Positions& positions,
                  std::vector<Problem>& problems) {
  for_each_key(
      c, [&](std::string_view table, std::string_view key, const auto& value, const auto& check) {
        collect(problems, positions, dotted(table, key),
                [&] { ValueChecker{report}(table, key, value, check); });
      });
  check_between_keys(c, report, [&](std::string_view key, const std::function<void()>& check) {
    collect(problems, positions, key, check);
  });
}

// Reads each known key from the document into the configuration, checking its type and that
// an integer fits its field, and records where it was.
struct FileReader {
  const toml::table& root;
  const Reporter& report;
  Positions& positions;

  const toml::node* find(std::string_view table, std::string_view key) const {
    const toml::node* holder = table.empty() ? &root : root.get(table);
    if (holder == nullptr || !holder->is_table()) return nullptr;
    const toml::node* node = holder->as_table()->get(key);
    if (node != nullptr) positions[dotted(table, key)] = node->source().begin;
    return node;
  }

  [[noreturn]] void wrong_type(const toml::node& n, std::string_view table, std::string_view key,
                               std::string_view expected) const {
    report.fail_at(n.source().begin, dotted(table, key),
                   fmt::format("expected {}, found {}", expected, type_name(n.type())));
  }

  static std::string_view type_name(toml::node_type t) {
    switch (t) {
      case toml::node_type::string:
        return "a string";
      case toml::node_type::integer:
        return "an integer";
      case toml::node_type::floating_point:
        return "a floating-point number";
      case toml::node_type::boolean:
        return "a boolean";
      case toml::node_type::table:
        return "a table";
      case toml::node_type::array:
        return "an array";
      default:
        return "a date or time";
    }
  }

  void operator()(std::string_view table, std::string_view key, std::string& out,
                  StringCheck) const {
    if (const auto* n = find(table, key)) {
      if (!n->is_string()) wrong_type(*n, table, key, "a string");
      out = n->as_string()->get();
    }
  }
  void operator()(std::string_view table, std::string_view key, bool& out, std::monostate) const {
    if (const auto* n = find(table, key)) {
      if (!n->is_boolean()) wrong_type(*n, table, key, "true or false");
      out = n->as_boolean()->get();
    }
  }
  template <typename Int>
  void operator()(std::string_view table, std::string_view key, Int& out, IntRange r) const {
    if (const auto* n = find(table, key)) {
      if (!n->is_integer()) wrong_type(*n, table, key, "an integer");
      const std::int64_t v = n->as_integer()->get();
      // Checked here, before narrowing, so 65537 cannot wrap to a valid port.
      if (v < r.lo || v > r.hi) {
        report.fail_at(n->source().begin, dotted(table, key),
                       fmt::format("{} is out of range ({}..{})", v, r.lo, r.hi));
      }
      out = static_cast<Int>(v);
    }
  }
  void operator()(std::string_view table, std::string_view key, double& out, RealRange) const {
    if (const auto* n = find(table, key)) {
      if (n->is_floating_point()) {
        out = n->as_floating_point()->get();
      } else if (n->is_integer()) {  // `max_range = 200` means 200.0
        out = static_cast<double>(n->as_integer()->get());
      } else {
        wrong_type(*n, table, key, "a number");
      }
    }
  }
};

// Every table and key in the document must be one the configuration has. Each that is not is a
// problem, with the nearest known name when one is near ("did you mean data_port?"), or the
// table a key belongs in when it was put in another.
std::vector<Problem> unknown_keys(const toml::table& root, const std::string& source_name) {
  std::map<std::string, std::vector<std::string_view>, std::less<>> known;
  DaemonConfig probe;
  for_each_key(probe, [&](std::string_view table, std::string_view key, auto&, auto) {
    known[std::string(table)].push_back(key);
  });
  std::vector<std::string_view> top_names;  // tables and top-level keys
  for (const auto& [table, keys] : known) {
    if (table.empty()) {
      top_names.insert(top_names.end(), keys.begin(), keys.end());
    } else {
      top_names.push_back(table);
    }
  }
  const auto hint = [&](std::string_view name, std::span<const std::string_view> candidates,
                        std::string_view table) -> std::string {
    if (const auto near = nearest(name, candidates))
      return fmt::format(" (did you mean {}?)", *near);
    for (const auto& [other, keys] : known) {
      if (other != table && std::find(keys.begin(), keys.end(), name) != keys.end()) {
        return other.empty() ? fmt::format(" ({} is a top-level key, before any table)", name)
                             : fmt::format(" ({} is a key of [{}])", name, other);
      }
    }
    return "";
  };
  std::vector<Problem> problems;
  const auto note = [&](const toml::source_position& at, const std::string& key,
                        const std::string& message) {
    problems.push_back(Problem{
        at, fmt::format("{}:{}:{}: {}: {}", source_name, at.line, at.column, key, message)});
  };
  const auto& top = known[""];
  for (const auto& [key, node] : root) {
    const std::string name(key.str());
    const auto table = known.find(name);
    if (table == known.end() || name.empty()) {
      if (std::find(top.begin(), top.end(), name) == top.end())
        note(key.source().begin, name, "unknown key or table" + hint(name, top_names, ""));
      continue;
    }
    if (!node.is_table()) {
      note(node.source().begin, name,
           fmt::format("expected a table, found {}", FileReader::type_name(node.type())));
      continue;
    }
    for (const auto& [inner, inner_node] : *node.as_table()) {
      const std::string_view inner_name = inner.str();
      if (std::find(table->second.begin(), table->second.end(), inner_name) ==
          table->second.end()) {
        note(inner.source().begin, dotted(name, inner_name),
             "unknown key" + hint(inner_name, table->second, name));
      }
    }
  }
  return problems;
}

// All the problems of a file at once, in the file's order, one per line.
void throw_if_any(std::vector<Problem>& problems) {
  if (problems.empty()) return;
  std::stable_sort(problems.begin(), problems.end(),
                   [](const Problem& a, const Problem& b) { return a.at < b.at; });
  std::string text;
  for (const Problem& p : problems) {
    if (!text.empty()) text += '\n';
    text += p.text;
  }
  throw ConfigError(text);
}

std::string toml_string(const std::string& s) {
  std::string out = "\"";
  for (const char c : s) {
    const auto u = static_cast<unsigned char>(c);
    if (c == '"' || c == '\\') {
      out += '\\';
      out += c;
    } else if (u < 0x20 || u == 0x7F) {
      out += fmt::format("\\u{:04X}", u);
    } else {
      out += c;
    }
  }
  return out + '"';
}

// Shortest text that reads back to the same double, always with a '.' or exponent so TOML
// reads it as a float.
std::string toml_real(double v) {
  std::string text = fmt::format("{}", v);
  if (text.find_first_of(".eEn") == std::string::npos) text += ".0";
  return text;
}

// toml++ parses nesting by recursion: a dotted key or table header some 40 000 levels deep (an
// 80 KB file) overflows the stack. A pandarcapd configuration nests two levels; anything past
// kMaxNesting is refused before toml++ sees it, at the character where the limit is crossed.
// Counted: open arrays and inline tables, plus the dots of the key or table header being read
// (dots inside strings and comments, and in values such as 1.5, are not keys and do not count).
constexpr int kMaxNesting = 32;

void reject_deep_nesting(std::string_view text, const std::string& source_name) {
  std::size_t line = 1, column = 0;
  int depth = 0;                    // open [ and {
  std::uint64_t inline_tables = 0;  // bit d: the bracket open at depth d+1 is a '{'
  bool in_key = true;               // before the '=' of a key, or inside a table header
  int key_dots = 0;
  const auto too_deep = [&] {
    throw ConfigError(fmt::format(
        "{}:{}:{}: nested more than {} levels deep (tables, dotted keys, arrays): not a "
        "pandarcapd configuration",
        source_name, line, column, kMaxNesting));
  };
  for (std::size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    ++column;
    if (c == '\n') {
      ++line;
      column = 0;
      if (depth == 0) {
        in_key = true;
        key_dots = 0;
      }
      continue;
    }
    if (c == '#') {  // comment: to the end of the line
      while (i + 1 < text.size() && text[i + 1] != '\n')
        ++i;
      continue;
    }
    if (c == '"' || c == '\'') {
      const bool multi_line = text.substr(i, 3) == std::string_view(c == '"' ? "\"\"\"" : "'''");
      const std::string_view close = multi_line ? text.substr(i, 3) : text.substr(i, 1);
      i += close.size() - 1;
      // To the closing quote(s); a basic string's backslash escapes the next character. An
      // unterminated string is left to toml++ to report.
      while (i + 1 < text.size()) {
        ++i;
        ++column;
        if (text[i] == '\n') {
          ++line;
          column = 0;
          if (!multi_line) break;
        } else if (c == '"' && text[i] == '\\') {
          ++i;
          ++column;
        } else if (text.substr(i, close.size()) == close) {
          i += close.size() - 1;
          column += close.size() - 1;
          break;
        }
      }
      continue;
    }
    switch (c) {
      case '[':
      case '{':
        if (depth + key_dots + 1 > kMaxNesting) too_deep();
        if (c == '{') {
          inline_tables |= std::uint64_t{1} << depth;
          in_key = true;  // an inline table's keys follow
          key_dots = 0;
        } else {
          inline_tables &= ~(std::uint64_t{1} << depth);
        }
        ++depth;
        break;
      case ']':
      case '}':
        if (depth > 0) --depth;
        if (c == '}') in_key = false;
        break;
      case ',':
        if (depth > 0 && (inline_tables >> (depth - 1) & 1) != 0) {
          in_key = true;
          key_dots = 0;
        }
        break;
      case '=':
        in_key = false;
        break;
      case '.':
        if (in_key && depth + ++key_dots + 1 > kMaxNesting) too_deep();
        break;
      default:
        break;
    }
  }
}

}  // namespace

DaemonConfig parse_config(std::string_view toml_text, const std::string& source_name) {
  reject_deep_nesting(toml_text, source_name);
  toml::table root;
  try {
    root = toml::parse(toml_text, source_name);
  } catch (const toml::parse_error& e) {
    const auto& at = e.source().begin;
    throw ConfigError(
        fmt::format("{}:{}:{}: {}", source_name, at.line, at.column, e.description()));
  }
  Positions positions;
  const Reporter report(source_name, &positions);
  std::vector<Problem> problems = unknown_keys(root, source_name);
  DaemonConfig config;
  const FileReader reader{root, report, positions};
  for_each_key(
      config, [&](std::string_view table, std::string_view key, auto& out, const auto& check) {
        collect(problems, positions, dotted(table, key), [&] { reader(table, key, out, check); });
      });
  // A key that could not be read keeps its default, which passes; what was read is checked.
  check_values(config, report, positions, problems);
  throw_if_any(problems);
  return config;
}

DaemonConfig load_config_file(const std::filesystem::path& path) {
  const TextFile file = read_text_file(path.string());
  switch (file.status) {
    case TextFile::Status::kOk:
      break;
    case TextFile::Status::kCannotOpen:
    case TextFile::Status::kCannotRead:
      throw ConfigError(
          fmt::format("{}: cannot read: {}", path.string(), std::strerror(file.error_number)));
    case TextFile::Status::kTooLarge:
      throw ConfigError(fmt::format("{}:1:1: larger than {} bytes: not a pandarcapd configuration",
                                    path.string(), kMaxOperatorFileBytes));
  }
  return parse_config(file.text, path.string());
}

namespace {

// Sets the one key named `key` from command-line text, with the type and range check the file's
// reader and checker apply to it.
struct TextSetter {
  std::string_view key;
  std::string_view text;
  const Reporter& report;
  bool found = false;

  bool matches(std::string_view table, std::string_view name) {
    if (found || dotted(table, name) != key) return false;
    found = true;
    return true;
  }
  [[noreturn]] void not_a(std::string_view what) const {
    report.fail(key, fmt::format("expected {}, found \"{}\"", what, text));
  }

  void operator()(std::string_view table, std::string_view name, std::string& out,
                  StringCheck check) {
    if (!matches(table, name)) return;
    std::string value(text);
    if (auto problem = check(value)) report.fail(key, *problem);
    out = std::move(value);
  }
  void operator()(std::string_view table, std::string_view name, bool& out, std::monostate) {
    if (!matches(table, name)) return;
    if (text != "true" && text != "false") not_a("true or false");
    out = text == "true";
  }
  template <typename Int>
  void operator()(std::string_view table, std::string_view name, Int& out, IntRange r) {
    if (!matches(table, name)) return;
    std::int64_t v = 0;
    const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), v);
    if (text.empty() || error != std::errc() || end != text.data() + text.size()) {
      not_a("an integer");
    }
    if (v < r.lo || v > r.hi) {
      report.fail(key, fmt::format("{} is out of range ({}..{})", v, r.lo, r.hi));
    }
    out = static_cast<Int>(v);
  }
  void operator()(std::string_view table, std::string_view name, double& out, const RealRange& r) {
    if (!matches(table, name)) return;
    const std::string value(text);
    char* end = nullptr;
    errno = 0;
    const double v = std::strtod(value.c_str(), &end);
    if (value.empty() || end != value.c_str() + value.size() || errno == ERANGE) {
      not_a("a number");
    }
    ValueChecker{report}(table, name, v, r);
    out = v;
  }
};

}  // namespace

void set_config_value(DaemonConfig& config, std::string_view key, std::string_view text,
                      const std::string& source_name) {
  const Reporter report(source_name, nullptr);
  TextSetter setter{key, text, report};
  for_each_key(config, setter);
  if (!setter.found) report.fail(key, "not a configuration key");
}

void validate_config(const DaemonConfig& config, const std::string& source_name) {
  std::vector<Problem> problems;
  check_values(config, Reporter(source_name, nullptr), Positions{}, problems);
  throw_if_any(problems);
}

std::string to_toml(const DaemonConfig& config) {
  std::string out = "# pandarcapd configuration (pandarcapd --print-config)\n";
  std::string_view current_table;
  for_each_key(config, [&](std::string_view table, std::string_view key, const auto& value, auto) {
    if (table != current_table) {
      out += fmt::format("\n[{}]\n", table);
      current_table = table;
    }
    using T = std::decay_t<decltype(value)>;
    if constexpr (std::is_same_v<T, std::string>) {
      out += fmt::format("{} = {}\n", key, toml_string(value));
    } else if constexpr (std::is_same_v<T, bool>) {
      out += fmt::format("{} = {}\n", key, value ? "true" : "false");
    } else if constexpr (std::is_same_v<T, double>) {
      out += fmt::format("{} = {}\n", key, toml_real(value));
    } else {
      out += fmt::format("{} = {}\n", key, value);
    }
  });
  return out;
}

}  // namespace pandarcap
