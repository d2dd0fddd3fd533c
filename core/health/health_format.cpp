#include "core/health/health_format.hpp"

#include <fmt/format.h>

#include <cmath>

#include "core/health/health_format_parts.hpp"
#include "core/ipv4.hpp"
#include "core/ptc/ptc_messages.hpp"
#include "core/ptc/status_plausibility.hpp"
#include "core/text_encoding.hpp"
#include "core/utc_time.hpp"

namespace pandarcap {

std::string_view to_string(HealthState state) noexcept {
  switch (state) {
    case HealthState::kOk:
      return "ok";
    case HealthState::kNoData:
      return "no_data";
    case HealthState::kDegraded:
      return "degraded";
    case HealthState::kError:
      return "error";
  }
  return "unknown";
}

namespace health_format {

void family(std::string& out, std::string_view name, std::string_view type, std::string_view help,
            std::string_view suffix) {
  fmt::format_to(std::back_inserter(out), "# HELP pandarcap_{}{} {}\n# TYPE pandarcap_{}{} {}\n",
                 name, suffix, help, name, suffix, type);
}

}  // namespace health_format

using health_format::family;
using health_format::storage_json;
using health_format::storage_prometheus;

namespace {

// One table drives both outputs, so a counter cannot appear in one and be forgotten in the other;
// it is generated from PANDARCAP_HEALTH_COUNTERS (core/health/health.hpp), as the fields are.
struct CounterField {
  const char* json;        // HealthCounters field name
  const char* prometheus;  // metric name without the pandarcap_ prefix and _total suffix
  std::uint64_t HealthCounters::*member;
  const char* help;
};

#define PANDARCAP_COUNTER_FIELD(field, prometheus_name, help) \
  {#field, prometheus_name, &HealthCounters::field, help},
constexpr CounterField kCounters[] = {PANDARCAP_HEALTH_COUNTERS(PANDARCAP_COUNTER_FIELD)};
#undef PANDARCAP_COUNTER_FIELD

struct GaugeField {
  const char* json;
  const char* prometheus;
  double HealthGauges::*member;
  const char* help;
};

constexpr GaugeField kGauges[] = {
    {"rpm_tail", "motor_speed_tail_rpm", &HealthGauges::rpm_tail,
     "Motor speed reported in the packet tails, last second"},
    {"rpm_measured", "motor_speed_measured_rpm", &HealthGauges::rpm_measured,
     "Motor speed measured from azimuth progression over packet time, last second"},
    {"frame_rate_hz", "frame_rate_hertz", &HealthGauges::frame_rate_hz,
     "Complete frames (full revolutions) cut per second, last second"},
    {"packet_rate_hz", "packet_rate_hertz", &HealthGauges::packet_rate_hz,
     "Packets per second by the sensor's own clock, last second; 0 while unknown"},
    {"seconds_since_last_packet", "seconds_since_last_packet",
     &HealthGauges::seconds_since_last_packet,
     "Seconds since the last accepted packet; -1 before the first"},
    {"uptime_seconds", "uptime_seconds", &HealthGauges::uptime_seconds,
     "Seconds since the daemon started"},
    {"receive_wakeups_per_second", "receive_wakeups_per_second",
     &HealthGauges::receive_wakeups_per_second, "Receive thread wake-ups, last second"},
    {"decode_wakeups_per_second", "decode_wakeups_per_second",
     &HealthGauges::decode_wakeups_per_second, "Decode thread wake-ups, last second"},
    {"writer_wakeups_per_second", "writer_wakeups_per_second",
     &HealthGauges::writer_wakeups_per_second, "Writer thread wake-ups, last second"},
};

// The counters the decoder does not count when nothing consumes points
// (HealthSnapshot::points_counted false): left out rather than rendered as 0.
constexpr bool counts_points(std::uint64_t HealthCounters::*member) {
  return member == &HealthCounters::points ||
         member == &HealthCounters::points_dropped_frame_full ||
         member == &HealthCounters::frames_complete || member == &HealthCounters::frames_partial ||
         member == &HealthCounters::frames_decimated ||
         member == &HealthCounters::frames_fragment || member == &HealthCounters::points_missing ||
         member == &HealthCounters::frameless_packets;
}

// Whether a counter or gauge is in this record (see counts_points).
bool rendered(const HealthSnapshot& h, std::uint64_t HealthCounters::*member) {
  return h.points_counted || !counts_points(member);
}
bool rendered(const HealthSnapshot& h, double HealthGauges::*member) {
  return h.points_counted || member != &HealthGauges::frame_rate_hz;
}

constexpr const char* kReturnModes[] = {"last", "strongest", "dual"};

// A LatencyHistogram as a Prometheus histogram with buckets at 2^first .. 2^last ns (exact
// bucket edges of the histogram).
void histogram(std::string& out, std::string_view sensor, std::string_view name,
               std::string_view help, const LatencyHistogram& h, int first, int last) {
  const auto append = [&out]<typename... Args>(fmt::format_string<Args...> format, Args&&... args) {
    fmt::format_to(std::back_inserter(out), format, std::forward<Args>(args)...);
  };
  family(out, name, "histogram", help, "");
  for (int p = first; p <= last; ++p) {
    append("pandarcap_{}_bucket{{{},le=\"{}\"}} {}\n", name, sensor, std::ldexp(1e-9, p),
           h.count_below_pow2(p));
  }
  append("pandarcap_{}_bucket{{{},le=\"+Inf\"}} {}\n", name, sensor, h.count());
  append("pandarcap_{}_sum{{{}}} {}\n", name, sensor, static_cast<double>(h.sum_ns()) / 1e9);
  append("pandarcap_{}_count{{{}}} {}\n", name, sensor, h.count());
}

// Percentiles (bucket upper edges, at most 12.5 % high; max exact) as a JSON object, in `unit`
// (1e3: microseconds, 1e6: milliseconds).
void latency_json(std::string& out, std::string_view key, const LatencyHistogram& h,
                  std::string_view unit, double ns_per_unit) {
  fmt::format_to(std::back_inserter(out), ",\"{}\":{{\"count\":{}", key, h.count());
  for (const auto& [name, q] :
       {std::pair{"p50", 0.5}, std::pair{"p99", 0.99}, std::pair{"p999", 0.999}}) {
    fmt::format_to(std::back_inserter(out), ",\"{}_{}\":", name, unit);
    append_json_number(out, static_cast<double>(h.quantile_ns(q)) / ns_per_unit);
  }
  fmt::format_to(std::back_inserter(out), ",\"max_{}\":", unit);
  append_json_number(out, static_cast<double>(h.max_ns()) / ns_per_unit);
  out += '}';
}

}  // namespace

namespace {

// The sensor's identity (always) and its PTC status (while polled; the values only while fresh).
void sensor_prometheus(std::string& out, std::string_view sensor, const HealthSnapshot& h) {
  const auto append = [&out]<typename... Args>(fmt::format_string<Args...> format, Args&&... args) {
    fmt::format_to(std::back_inserter(out), format, std::forward<Args>(args)...);
  };
  const SensorIdentity& id = h.sensor_identity;
  family(out, "sensor_info", "gauge",
         "The sensor's serial number and firmware (from PTC; empty when not asked or not "
         "answering) and where the calibration in use came from; always 1");
  append("pandarcap_sensor_info{{{},serial=\"", sensor);
  append_label_value(out, id.serial);
  out += "\",firmware=\"";
  append_label_value(out, id.firmware);
  out += "\",calibration_source=\"";
  append_label_value(out, id.calibration_source);
  out += "\"} 1\n";

  if (h.gauges.sensor_clock_offset_known) {
    family(out, "sensor_clock_offset_seconds", "gauge",
           "The sensor's clock minus the host's: the last packet's time minus its kernel receive "
           "time (a replay: its capture time)");
    append("pandarcap_sensor_clock_offset_seconds{{{}}} {}\n", sensor,
           h.gauges.sensor_clock_offset_seconds);
  }

  const SensorStatusGauges& st = h.gauges.sensor_status;
  if (!st.polled) return;
  family(out, "sensor_status_age_seconds", "gauge",
         "Seconds since the sensor last answered a status request over PTC; -1 before the first");
  append("pandarcap_sensor_status_age_seconds{{{}}} {}\n", sensor, st.age_seconds);
  family(out, "sensor_status_stale", "gauge",
         "1 when the last status is older than 3 polling intervals (its values are not reported)");
  append("pandarcap_sensor_status_stale{{{}}} {}\n", sensor, st.stale ? 1 : 0);
  if (!st.available || st.stale) return;
  // A field outside its physical range is left out (core/ptc/status_plausibility.hpp).
  const auto plausible = [&](std::uint32_t bit) { return (st.implausible >> bit & 1u) == 0; };
  if (plausible(ptc::kUptimeBit)) {
    family(out, "sensor_uptime_seconds", "gauge", "The sensor's own uptime (PTC status)");
    append("pandarcap_sensor_uptime_seconds{{{}}} {}\n", sensor, st.uptime_seconds);
  }
  if (plausible(ptc::kMotorBit)) {
    family(out, "sensor_motor_speed_rpm", "gauge", "Motor speed the sensor reports (PTC status)");
    append("pandarcap_sensor_motor_speed_rpm{{{}}} {}\n", sensor, st.motor_rpm);
  }
  family(out, "sensor_temperature_celsius", "gauge",
         "The sensor's board temperatures (PTC status), by board and sensor");
  for (std::size_t i = 0; i < ptc::kTemperatureCount; ++i) {
    if (!plausible(ptc::kTemperatureBit0 + static_cast<std::uint32_t>(i))) continue;
    append("pandarcap_sensor_temperature_celsius{{{},board=\"{}\"}} {}\n", sensor,
           ptc::kTemperatureNames[i], st.temperatures_celsius[i]);
  }
  if (plausible(ptc::kGpsPpsBit)) {
    family(out, "sensor_gps_pps_locked", "gauge", "1 when the sensor reports its GPS PPS locked");
    append("pandarcap_sensor_gps_pps_locked{{{}}} {}\n", sensor, st.gps_pps_locked ? 1 : 0);
  }
  if (plausible(ptc::kPtpStateBit)) {
    family(out, "sensor_ptp_state", "gauge",
           "1 for the sensor's PTP clock state (free_run, tracking, locked, frozen)");
    for (std::uint8_t i = 0; i < ptc::kPtpStateCount; ++i) {
      append("pandarcap_sensor_ptp_state{{{},state=\"{}\"}} {}\n", sensor, ptc::ptp_state_name(i),
             st.ptp_state == i ? 1 : 0);
    }
  }
  if (st.ptp_offset_known) {
    family(out, "sensor_ptp_offset_seconds", "gauge",
           "The sensor's PTP offset from its master (PTC PTP diagnostics, where answered)");
    append("pandarcap_sensor_ptp_offset_seconds{{{}}} {}\n", sensor, st.ptp_offset_seconds);
  }
  if (st.clock_source_known) {
    family(out, "sensor_clock_source", "gauge",
           "1 for the clock source the sensor is configured to follow (gps, ptp)");
    append("pandarcap_sensor_clock_source{{{},source=\"gps\"}} {}\n", sensor,
           st.clock_source_ptp ? 0 : 1);
    append("pandarcap_sensor_clock_source{{{},source=\"ptp\"}} {}\n", sensor,
           st.clock_source_ptp ? 1 : 0);
  }
}

void sensor_json(std::string& out, const HealthSnapshot& h) {
  const auto append = [&out]<typename... Args>(fmt::format_string<Args...> format, Args&&... args) {
    fmt::format_to(std::back_inserter(out), format, std::forward<Args>(args)...);
  };
  const SensorIdentity& id = h.sensor_identity;
  out += ",\"sensor_info\":{\"serial\":";
  append_json_string(out, id.serial);
  out += ",\"firmware\":";
  append_json_string(out, id.firmware);
  out += ",\"calibration_source\":";
  append_json_string(out, id.calibration_source);
  out += "}";
  const SensorStatusGauges& st = h.gauges.sensor_status;
  append(",\"sensor_status\":{{\"polled\":{},\"available\":{},\"stale\":{},\"age_seconds\":",
         st.polled, st.available, st.stale);
  append_json_number(out, st.age_seconds);
  if (st.polled && st.available && !st.stale) {
    // A field outside its physical range is left out, and named in "implausible".
    const auto plausible = [&](std::uint32_t bit) { return (st.implausible >> bit & 1u) == 0; };
    if (plausible(ptc::kUptimeBit)) {
      out += ",\"uptime_seconds\":";
      append_json_number(out, st.uptime_seconds);
    }
    if (plausible(ptc::kMotorBit)) {
      out += ",\"motor_rpm\":";
      append_json_number(out, st.motor_rpm);
    }
    out += ",\"temperatures_celsius\":{";
    bool first = true;
    for (std::size_t i = 0; i < ptc::kTemperatureCount; ++i) {
      if (!plausible(ptc::kTemperatureBit0 + static_cast<std::uint32_t>(i))) continue;
      append("{}\"{}\":", first ? "" : ",", ptc::kTemperatureNames[i]);
      append_json_number(out, st.temperatures_celsius[i]);
      first = false;
    }
    out += '}';
    if (plausible(ptc::kGpsPpsBit)) append(",\"gps_pps_locked\":{}", st.gps_pps_locked);
    if (plausible(ptc::kGpsNmeaBit)) append(",\"gps_nmea_locked\":{}", st.gps_nmea_locked);
    if (plausible(ptc::kPtpStateBit))
      append(",\"ptp_state\":\"{}\"", ptc::ptp_state_name(st.ptp_state));
    if (st.implausible != 0) {
      out += ",\"implausible\":[";
      bool first_name = true;
      for (std::uint32_t bit = 0; bit <= ptc::kPtpStateBit; ++bit) {
        if (plausible(bit)) continue;
        out += first_name ? "\"" : ",\"";
        ptc::append_field_name(bit, out);
        out += '"';
        first_name = false;
      }
      out += ']';
    }
    if (st.ptp_offset_known) {
      out += ",\"ptp_offset_seconds\":";
      append_json_number(out, st.ptp_offset_seconds);
    }
  }
  if (st.clock_source_known)
    append(",\"clock_source\":\"{}\"", st.clock_source_ptp ? "ptp" : "gps");
  out += "}";
}

}  // namespace

void render_prometheus(const HealthSnapshot& h, std::string& out) {
  out.clear();
  // The sensor label, escaped once per file into a stack buffer (a name longer than ~250
  // characters would spill to the heap; nothing shorter allocates).
  fmt::basic_memory_buffer<char, 512> label;
  fmt::format_to(std::back_inserter(label), "sensor=\"");
  append_label_value(label, h.sensor);
  label.push_back('"');
  const std::string_view sensor(label.data(), label.size());
  const auto append = [&out]<typename... Args>(fmt::format_string<Args...> format, Args&&... args) {
    fmt::format_to(std::back_inserter(out), format, std::forward<Args>(args)...);
  };

  family(out, "build_info", "gauge", "pandarcap version and decoder target; always 1");
  append("pandarcap_build_info{{{},version=\"", sensor);
  append_label_value(out, h.version);
  out += "\",decoder=\"";
  append_label_value(out, h.decoder);
  out += "\"} 1\n";
  sensor_prometheus(out, sensor, h);

  family(out, "points_counted", "gauge",
         "1 when points are decoded and frames cut; 0 when nothing consumes them (output.frames "
         "and output.mcap off): the point and frame counters are then left out");
  append("pandarcap_points_counted{{{}}} {}\n", sensor, h.points_counted ? 1 : 0);
  for (const CounterField& f : kCounters) {
    if (!rendered(h, f.member)) continue;
    family(out, f.prometheus, "counter", f.help, "_total");
    append("pandarcap_{}_total{{{}}} {}\n", f.prometheus, sensor, h.counters.*f.member);
  }
  family(out, "file_create_cpu_seconds_total", "counter",
         "CPU the creation of the files_created took: the file system's cost, dear on ext4 without "
         "a journal after many deletions (docs/deploy.md)");
  append("pandarcap_file_create_cpu_seconds_total{{{}}} {}.{:06}\n", sensor,
         h.counters.file_create_cpu_us / 1'000'000, h.counters.file_create_cpu_us % 1'000'000);
  family(out, "packets_rejected_total", "counter", "Packets that failed validation, by reason");
  for (std::size_t i = 1; i < kRejectReasonCount; ++i) {  // 0 is kNone
    append("pandarcap_packets_rejected_total{{{},reason=\"{}\"}} {}\n", sensor,
           to_string(static_cast<RejectReason>(i)), h.counters.rejects[i]);
  }
  if (h.points_counted) {
    family(out, "points_filtered_total", "counter", "Points filtered out, by reason");
    for (std::size_t i = 0; i < kFilterReasonCount; ++i) {
      append("pandarcap_points_filtered_total{{{},reason=\"{}\"}} {}\n", sensor,
             to_string(static_cast<FilterReason>(i)), h.counters.filtered_points[i]);
    }
  }

  for (const GaugeField& f : kGauges) {
    if (!rendered(h, f.member)) continue;
    family(out, f.prometheus, "gauge", f.help);
    append("pandarcap_{}{{{}}} {}\n", f.prometheus, sensor, h.gauges.*f.member);
  }
  family(out, "high_temperature", "gauge", "1 when the last packet had the high-temperature flag");
  append("pandarcap_high_temperature{{{}}} {}\n", sensor, h.gauges.high_temperature ? 1 : 0);
  family(out, "return_mode", "gauge", "1 for the return mode of the last packet");
  for (const char* mode : kReturnModes) {
    append("pandarcap_return_mode{{{},mode=\"{}\"}} {}\n", sensor, mode,
           h.gauges.return_mode == mode ? 1 : 0);
  }
  family(out, "state", "gauge", "1 for the daemon's current health state");
  for (std::size_t i = 0; i < kHealthStateCount; ++i) {
    const auto state = static_cast<HealthState>(i);
    append("pandarcap_state{{{},state=\"{}\"}} {}\n", sensor, to_string(state),
           h.gauges.state == state ? 1 : 0);
  }

  storage_prometheus(out, sensor, h.gauges.storage);
  family(out, "health_fallback", "gauge",
         "1 while the health files are written to health.fallback_directory (their own directory "
         "cannot be written)");
  append("pandarcap_health_fallback{{{}}} {}\n", sensor, h.gauges.health_fallback.active ? 1 : 0);
  if (const auto& live = h.live) {
    family(out, "live_listening", "gauge",
           "1 while the live view listens; 0 while its port cannot be bound (retrying)");
    append("pandarcap_live_listening{{{}}} {}\n", sensor, live->listening ? 1 : 0);
    family(out, "live_clients", "gauge", "Foxglove viewers connected to the live view");
    append("pandarcap_live_clients{{{}}} {}\n", sensor, live->clients);
    family(out, "live_messages_sent_total", "counter", "Messages the live view sent its viewers");
    append("pandarcap_live_messages_sent_total{{{}}} {}\n", sensor, live->messages_sent);
    family(
        out, "live_messages_dropped_total", "counter",
        "Messages a live viewer did not get: its send queue full, or a frame replaced by the next");
    append("pandarcap_live_messages_dropped_total{{{}}} {}\n", sensor, live->messages_dropped);
  }

  if (const auto& a = h.hot_path_allocations) {
    family(out, "hot_path_allocations_total", "counter",
           "Heap allocations in the receive, decode and writer loops after warm-up, by thread");
    for (const auto& [thread, n] :
         {std::pair{"receive", a->receive}, std::pair{"decode", a->decode},
          std::pair{"writer", a->writer}}) {
      append("pandarcap_hot_path_allocations_total{{{},thread=\"{}\"}} {}\n", sensor, thread, n);
    }
  }

  // Buckets at powers of two (exact edges of the histogram): 8.2 µs .. 1.07 s per packet,
  // 1 ms .. 8.6 s per frame.
  histogram(out, sensor, "receive_to_decoded_latency_seconds",
            "Kernel receive timestamp to decoded, per packet (live capture only)", h.latency, 13,
            30);
  histogram(out, sensor, "frame_latency_seconds",
            "Kernel receive timestamp of the packet that completed a frame to its PCD file in "
            "place (live capture only)",
            h.frame_latency, 20, 33);
}

void render_json_line(const HealthSnapshot& h, std::string& out) {
  out.clear();
  const auto append = [&out]<typename... Args>(fmt::format_string<Args...> format, Args&&... args) {
    fmt::format_to(std::back_inserter(out), format, std::forward<Args>(args)...);
  };
  out += "{\"time\":\"";
  append_rfc3339(out, h.unix_time_ns, 3);
  append("\",\"unix_time_ns\":{},\"sensor\":", h.unix_time_ns);
  append_json_string(out, h.sensor);
  out += ",\"version\":";
  append_json_string(out, h.version);
  out += ",\"decoder\":";
  append_json_string(out, h.decoder);
  append(",\"state\":\"{}\",\"reason\":", to_string(h.gauges.state));
  append_json_string(out, h.gauges.reason);
  append(",\"points_counted\":{}", h.points_counted);

  out += ",\"counters\":{";
  bool first = true;
  for (const CounterField& f : kCounters) {
    if (!rendered(h, f.member)) continue;
    append("{}\"{}\":{}", first ? "" : ",", f.json, h.counters.*f.member);
    first = false;
  }
  append(",\"packets_rejected\":{},\"file_create_cpu_us\":{}", h.counters.packets_rejected,
         h.counters.file_create_cpu_us);
  if (const auto& a = h.hot_path_allocations) {
    append(
        ",\"hot_path_allocations\":{},\"hot_path_allocations_by_thread\":"
        "{{\"receive\":{},\"decode\":{},\"writer\":{}}}",
        a->total(), a->receive, a->decode, a->writer);
  }
  out += ",\"rejects\":{";
  for (std::size_t i = 1; i < kRejectReasonCount; ++i) {
    append("{}\"{}\":{}", i == 1 ? "" : ",", to_string(static_cast<RejectReason>(i)),
           h.counters.rejects[i]);
  }
  out += '}';
  if (h.points_counted) {
    out += ",\"filtered_points\":{";
    for (std::size_t i = 0; i < kFilterReasonCount; ++i) {
      append("{}\"{}\":{}", i == 0 ? "" : ",", to_string(static_cast<FilterReason>(i)),
             h.counters.filtered_points[i]);
    }
    out += '}';
  }
  out += '}';

  out += ",\"gauges\":{";
  first = true;
  for (const GaugeField& f : kGauges) {
    if (!rendered(h, f.member)) continue;
    append("{}\"{}\":", first ? "" : ",", f.json);
    append_json_number(out, h.gauges.*f.member);
    first = false;
  }
  out += ",\"return_mode\":";
  append_json_string(out, h.gauges.return_mode);
  // The sensor's source, and another sensor's (core/decode/source_lock.hpp): "a.b.c.d:port" or
  // null.
  out += ",\"last_invalid_time\":";
  if (h.gauges.last_invalid_time.empty()) {
    out += "null";
  } else {
    append_json_string(out, h.gauges.last_invalid_time);
  }
  out += ",\"sensor_source\":";
  append_ipv4_source_json(out, h.gauges.sensor_source);
  out += ",\"other_sensor_source\":";
  append_ipv4_source_json(out, h.gauges.other_sensor_source);
  append(",\"high_temperature\":{}", h.gauges.high_temperature);
  if (h.gauges.sensor_clock_offset_known) {
    out += ",\"sensor_clock_offset_seconds\":";
    append_json_number(out, h.gauges.sensor_clock_offset_seconds);
  }
  out += '}';

  sensor_json(out, h);
  storage_json(out, h.gauges.storage);
  const HealthFallbackGauges& fallback = h.gauges.health_fallback;
  append(R"(,"health_fallback":{{"active":{})", fallback.active);
  if (fallback.active) {
    out += ",\"directory\":";
    append_json_string(out, fallback.directory);
    out += ",\"error\":";
    append_json_string(out, fallback.error);
  }
  out += '}';
  if (const auto& live = h.live) {
    append(R"(,"live":{{"listening":{},"clients":{},"messages_sent":{},"messages_dropped":{}}})",
           live->listening, live->clients, live->messages_sent, live->messages_dropped);
  }
  latency_json(out, "latency", h.latency, "us", 1e3);
  latency_json(out, "frame_latency", h.frame_latency, "ms", 1e6);
  out += "}\n";
}

std::string to_prometheus(const HealthSnapshot& h) {
  std::string out;
  render_prometheus(h, out);
  return out;
}

std::string to_json_line(const HealthSnapshot& h) {
  std::string out;
  render_json_line(h, out);
  return out;
}

}  // namespace pandarcap
