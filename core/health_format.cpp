#include "health_format.hpp"

#include <fmt/format.h>

#include <cmath>
#include <ctime>
#include <nlohmann/json.hpp>

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

namespace {

// One table drives both outputs, so a counter cannot appear in one and be forgotten in the other.
struct CounterField {
  const char* json;        // HealthCounters field name
  const char* prometheus;  // metric name without the pandarcap_ prefix and _total suffix
  std::uint64_t HealthCounters::*member;
  const char* help;
};

// clang-format off
constexpr CounterField kCounters[] = {
  {"datagrams_received", "datagrams_received", &HealthCounters::datagrams_received,
   "UDP datagrams delivered by the socket or the replay, from any source"},
  {"bytes_received", "received_bytes", &HealthCounters::bytes_received,
   "UDP payload bytes received, before truncation"},
  {"foreign_datagrams", "foreign_datagrams", &HealthCounters::foreign_datagrams,
   "Datagrams from a source other than sensor_ip, dropped"},
  {"truncated_datagrams", "truncated_datagrams", &HealthCounters::truncated_datagrams,
   "Datagrams larger than a ring slot (also rejected as bad_length)"},
  {"kernel_drops", "kernel_drops", &HealthCounters::kernel_drops,
   "Datagrams the kernel dropped because the socket buffer was full"},
  {"ring_overruns", "ring_overruns", &HealthCounters::ring_overruns,
   "Datagrams dropped by the receive thread because the ring was full"},
  {"packets_accepted", "packets_accepted", &HealthCounters::packets_accepted,
   "Packets that passed validation and were decoded"},
  {"sequence_gaps", "sequence_gaps", &HealthCounters::sequence_gaps,
   "Jumps forward in the UDP sequence number"},
  {"sequence_lost", "sequence_lost_packets", &HealthCounters::sequence_lost,
   "Packets missing from the UDP sequence (late arrivals forgiven)"},
  {"sequence_duplicates", "sequence_duplicate_packets", &HealthCounters::sequence_duplicates,
   "Packets whose UDP sequence number had already arrived"},
  {"sequence_reordered", "sequence_reordered_packets", &HealthCounters::sequence_reordered,
   "Packets that arrived after a later sequence number"},
  {"sequence_resets", "sequence_resets", &HealthCounters::sequence_resets,
   "Large jumps in the UDP sequence taken as a sensor restart"},
  {"azimuth_gaps", "azimuth_gaps", &HealthCounters::azimuth_gaps,
   "Azimuth jumps larger than one packet's worth (packets without a UDP sequence)"},
  {"static_timestamp_packets", "static_timestamp_packets",
   &HealthCounters::static_timestamp_packets, "Packets whose time did not advance"},
  {"invalid_time_packets", "invalid_time_packets", &HealthCounters::invalid_time_packets,
   "Packets with an impossible tail date or microsecond field"},
  {"high_temperature_packets", "high_temperature_packets",
   &HealthCounters::high_temperature_packets, "Packets with the high-temperature flag set"},
  {"return_mode_changes", "return_mode_changes", &HealthCounters::return_mode_changes,
   "Changes of the return mode between packets"},
  {"points", "points", &HealthCounters::points, "Points decoded and kept"},
  {"points_dropped_frame_full", "points_dropped_frame_full",
   &HealthCounters::points_dropped_frame_full, "Points dropped because the frame arena was full"},
  {"frames_complete", "frames_complete", &HealthCounters::frames_complete,
   "Frames cut with a full revolution"},
  {"frames_partial", "frames_partial", &HealthCounters::frames_partial,
   "Frames cut short (stream start, gap, shutdown)"},
  {"frames_dropped_no_arena", "frames_dropped_no_arena",
   &HealthCounters::frames_dropped_no_arena, "Frames dropped because no arena was free"},
  {"frames_dropped_writer_busy", "frames_dropped_writer_busy",
   &HealthCounters::frames_dropped_writer_busy, "Frames dropped because the writer queue was full"},
  {"frames_decimated", "frames_decimated", &HealthCounters::frames_decimated,
   "Frames skipped on purpose (frame_decimation)"},
  {"frames_written", "frames_written", &HealthCounters::frames_written, "PCD files completed"},
  {"pcap_packets_written", "pcap_packets_written", &HealthCounters::pcap_packets_written,
   "Packets recorded in pcap files"},
  {"pcap_packets_not_recorded", "pcap_packets_not_recorded",
   &HealthCounters::pcap_packets_not_recorded,
   "Packets left out of the pcap because the writer was behind"},
  {"pcap_bytes_written", "pcap_written_bytes", &HealthCounters::pcap_bytes_written,
   "Bytes written to pcap files"},
  {"pcd_bytes_written", "pcd_written_bytes", &HealthCounters::pcd_bytes_written,
   "Bytes written to PCD files"},
  {"write_errors", "write_errors", &HealthCounters::write_errors, "Failed writes"},
  {"bytes_not_written", "not_written_bytes", &HealthCounters::bytes_not_written,
   "Bytes lost to failed writes"},
};
// clang-format on

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
    {"seconds_since_last_packet", "seconds_since_last_packet",
     &HealthGauges::seconds_since_last_packet,
     "Seconds since the last accepted packet; -1 before the first"},
    {"uptime_seconds", "uptime_seconds", &HealthGauges::uptime_seconds,
     "Seconds since the daemon started"},
};

constexpr const char* kReturnModes[] = {"last", "strongest", "dual"};

void family(std::string& out, std::string_view name, std::string_view type, std::string_view help) {
  fmt::format_to(std::back_inserter(out), "# HELP pandarcap_{} {}\n# TYPE pandarcap_{} {}\n", name,
                 help, name, type);
}

std::string rfc3339(std::int64_t unix_ns) {
  const std::time_t seconds = static_cast<std::time_t>(unix_ns / 1'000'000'000);
  const auto millis = static_cast<int>((unix_ns % 1'000'000'000) / 1'000'000);
  std::tm tm{};
  gmtime_r(&seconds, &tm);
  return fmt::format("{:04}-{:02}-{:02}T{:02}:{:02}:{:02}.{:03}Z", tm.tm_year + 1900, tm.tm_mon + 1,
                     tm.tm_mday, tm.tm_hour, tm.tm_min, tm.tm_sec, millis);
}

}  // namespace

std::string escape_label_value(std::string_view value) {
  std::string out;
  out.reserve(value.size());
  for (const char c : value) {
    if (c == '\\') {
      out += "\\\\";
    } else if (c == '"') {
      out += "\\\"";
    } else if (c == '\n') {
      out += "\\n";
    } else {
      out += c;
    }
  }
  return out;
}

std::string to_prometheus(const HealthSnapshot& h) {
  std::string out;
  out.reserve(16 * 1024);
  const std::string sensor = fmt::format("sensor=\"{}\"", escape_label_value(h.sensor));
  const auto append = [&out]<typename... Args>(fmt::format_string<Args...> format, Args&&... args) {
    fmt::format_to(std::back_inserter(out), format, std::forward<Args>(args)...);
  };

  family(out, "build_info", "gauge", "pandarcap version and decoder target; always 1");
  append("pandarcap_build_info{{{},version=\"{}\",decoder=\"{}\"}} 1\n", sensor,
         escape_label_value(h.version), escape_label_value(h.decoder));

  for (const CounterField& f : kCounters) {
    family(out, std::string(f.prometheus) + "_total", "counter", f.help);
    append("pandarcap_{}_total{{{}}} {}\n", f.prometheus, sensor, h.counters.*f.member);
  }
  family(out, "packets_rejected_total", "counter", "Packets that failed validation, by reason");
  for (std::size_t i = 1; i < kRejectReasonCount; ++i) {  // 0 is kNone
    append("pandarcap_packets_rejected_total{{{},reason=\"{}\"}} {}\n", sensor,
           to_string(static_cast<RejectReason>(i)), h.counters.rejects[i]);
  }
  family(out, "points_filtered_total", "counter", "Points filtered out, by reason");
  for (std::size_t i = 0; i < kFilterReasonCount; ++i) {
    append("pandarcap_points_filtered_total{{{},reason=\"{}\"}} {}\n", sensor,
           to_string(static_cast<FilterReason>(i)), h.counters.filtered_points[i]);
  }

  for (const GaugeField& f : kGauges) {
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

  if (const auto& a = h.hot_path_allocations) {
    family(out, "hot_path_allocations_total", "counter",
           "Heap allocations in the receive, decode and writer loops after warm-up, by thread");
    for (const auto& [thread, n] :
         {std::pair{"receive", a->receive}, std::pair{"decode", a->decode},
          std::pair{"writer", a->writer}}) {
      append("pandarcap_hot_path_allocations_total{{{},thread=\"{}\"}} {}\n", sensor, thread, n);
    }
  }

  // Buckets at powers of two (exact edges of the histogram), 8.2 µs .. 1.07 s.
  family(out, "receive_to_decoded_latency_seconds", "histogram",
         "Kernel receive timestamp to decoded, per packet (live capture only)");
  for (int p = 13; p <= 30; ++p) {
    append("pandarcap_receive_to_decoded_latency_seconds_bucket{{{},le=\"{}\"}} {}\n", sensor,
           std::ldexp(1e-9, p), h.latency.count_below_pow2(p));
  }
  append("pandarcap_receive_to_decoded_latency_seconds_bucket{{{},le=\"+Inf\"}} {}\n", sensor,
         h.latency.count());
  append("pandarcap_receive_to_decoded_latency_seconds_sum{{{}}} {}\n", sensor,
         static_cast<double>(h.latency.sum_ns()) / 1e9);
  append("pandarcap_receive_to_decoded_latency_seconds_count{{{}}} {}\n", sensor,
         h.latency.count());
  return out;
}

std::string to_json_line(const HealthSnapshot& h) {
  nlohmann::ordered_json j;
  j["time"] = rfc3339(h.unix_time_ns);
  j["unix_time_ns"] = h.unix_time_ns;
  j["sensor"] = h.sensor;
  j["version"] = h.version;
  j["decoder"] = h.decoder;
  j["state"] = to_string(h.gauges.state);
  j["reason"] = h.gauges.reason;
  nlohmann::ordered_json counters;
  for (const CounterField& f : kCounters)
    counters[f.json] = h.counters.*f.member;
  counters["packets_rejected"] = h.counters.packets_rejected;
  if (const auto& a = h.hot_path_allocations) {
    counters["hot_path_allocations"] = a->total();
    counters["hot_path_allocations_by_thread"] = {
        {"receive", a->receive}, {"decode", a->decode}, {"writer", a->writer}};
  }
  for (std::size_t i = 1; i < kRejectReasonCount; ++i) {
    counters["rejects"][std::string(to_string(static_cast<RejectReason>(i)))] =
        h.counters.rejects[i];
  }
  for (std::size_t i = 0; i < kFilterReasonCount; ++i) {
    counters["filtered_points"][std::string(to_string(static_cast<FilterReason>(i)))] =
        h.counters.filtered_points[i];
  }
  j["counters"] = std::move(counters);
  nlohmann::ordered_json gauges;
  for (const GaugeField& f : kGauges)
    gauges[f.json] = h.gauges.*f.member;
  gauges["return_mode"] = h.gauges.return_mode;
  gauges["high_temperature"] = h.gauges.high_temperature;
  j["gauges"] = std::move(gauges);
  // Percentiles are bucket upper edges (at most 12.5 % high); max is exact.
  const auto us = [&](double q) { return static_cast<double>(h.latency.quantile_ns(q)) / 1e3; };
  j["latency"] = {{"count", h.latency.count()},
                  {"p50_us", us(0.5)},
                  {"p99_us", us(0.99)},
                  {"p999_us", us(0.999)},
                  {"max_us", static_cast<double>(h.latency.max_ns()) / 1e3}};
  // A reason may hold bytes from an error message that are not UTF-8: replace, never throw.
  return j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace) + "\n";
}

}  // namespace pandarcap
