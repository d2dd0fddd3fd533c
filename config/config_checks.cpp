#include "config/config_checks.hpp"

#include <fmt/format.h>

#include <algorithm>

namespace pandarcap::config_detail {
namespace {

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
  each("input.receiver", [&] {
    if (c.input.receiver == "packet_ring" && s.interface.empty()) {
      report.fail("input.receiver",
                  "\"packet_ring\" needs sensor.interface (--interface IFACE: the network "
                  "interface the sensor's packets arrive on; lo for a sensor on this host)");
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

}  // namespace

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

void throw_if_any(std::vector<Problem>& problems) {
  if (problems.empty()) return;
  std::stable_sort(problems.begin(), problems.end(),
                   [](const Problem& a, const Problem& b) { return a.at < b.at; });
  std::vector<std::string> lines;
  lines.reserve(problems.size());
  for (const Problem& p : problems)
    lines.push_back(p.text);
  throw ConfigError::lines(lines);
}

}  // namespace pandarcap::config_detail
