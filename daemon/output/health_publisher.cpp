#include "daemon/output/health_publisher.hpp"

#include <cerrno>
#include <cstdio>
#include <filesystem>
#include <system_error>

#include "core/health_format.hpp"
#include "core/health_policy.hpp"
#include "core/units.hpp"
#include "daemon/allocation_counter.hpp"
#include "daemon/clocks.hpp"
#include "daemon/output/output_directories.hpp"

namespace pandarcap {
HealthPublisher::HealthPublisher(const WriterOptions& options, OutputAccounting& accounting,
                                 SpaceGuard& space)
    : options_(options), accounting_(accounting), space_(space) {}

void HealthPublisher::prepare(std::int64_t start_monotonic_ns) {
  start_monotonic_ns_ = start_monotonic_ns;
  last_tick_ns_ = start_monotonic_ns;
  decode_prev_.monotonic_ns = start_monotonic_ns;
  prom_path_ = options_.prometheus_file.native();
  assign_temporary_name(prom_temporary_path_, prom_path_);
  jsonl_path_ = (options_.health_dir / "health.jsonl").native();
  jsonl_rotated_path_ = jsonl_path_ + ".1";
  health_.sensor_identity = options_.sensor_identity;  // found at start-up, constant after
  prom_text_.reserve(64 * 1024);
  json_text_.reserve(8 * 1024);
  // The reasons are rebuilt in place every second; room for every problem at once (a write
  // error's message with its path included), so the first degraded second, long after the loop
  // is warm, does not allocate.
  health_.gauges.reason.reserve(8 * 1024);
  health_.gauges.sensor_status.implausible_reason.reserve(1024);
}

namespace {

// The poller's latest answer, aged: values are kept in the record only while fresh.
void fill_sensor_status(const SensorStatusSample* latest, std::int64_t now, SensorStatusGauges& st,
                        bool polled, double interval_seconds) {
  st.polled = polled;
  st.interval_seconds = interval_seconds;
  st.available = latest != nullptr;
  if (latest == nullptr) {
    st.age_seconds = -1;
    st.stale = false;
    return;
  }
  st.age_seconds = static_cast<double>(now - latest->monotonic_ns) / 1e9;
  st.stale = interval_seconds > 0 && st.age_seconds > 3 * interval_seconds;
  set_status_fields(st, latest->status);
  st.ptp_offset_known = latest->ptp_offset_ns.has_value();
  st.ptp_offset_seconds = static_cast<double>(latest->ptp_offset_ns.value_or(0)) / 1e9;
  st.clock_source_known = latest->clock_source.has_value();
  st.clock_source_ptp = latest->clock_source == ptc::kClockSourcePtp;
}

}  // namespace

void HealthPublisher::build(const HealthSources& sources, std::int64_t now) {
  // Filled in place: its strings keep their capacity from one second to the next.
  HealthSnapshot& h = health_;
  json_text_current_ = false;
  const ReceiveCounters& receive = sources.receive;
  const DecodeSnapshot& decode = sources.decode;
  h.unix_time_ns = realtime_ns();
  h.sensor = options_.sensor_name;
  h.version = options_.version;
  h.decoder = options_.decoder;
  h.points_counted = options_.points_counted;
  HealthCounters& c = h.counters;
  h.latency = decode.latency;
  if (alloc::counting_available()) {
    h.hot_path_allocations = HotPathAllocations{alloc::hot_allocations(alloc::HotThread::kReceive),
                                                alloc::hot_allocations(alloc::HotThread::kDecode),
                                                alloc::hot_allocations(alloc::HotThread::kWriter)};
  }
  if (sources.live != nullptr) {
    h.live = LiveViewHealth{sources.live->clients.load(std::memory_order_relaxed),
                            sources.live->messages_sent.load(std::memory_order_relaxed),
                            sources.live->messages_dropped.load(std::memory_order_relaxed)};
  }
  c.datagrams_received = receive.datagrams.load(std::memory_order_relaxed);
  c.bytes_received = receive.bytes.load(std::memory_order_relaxed);
  c.foreign_datagrams = receive.foreign.load(std::memory_order_relaxed);
  c.truncated_datagrams = receive.truncated.load(std::memory_order_relaxed);
  c.kernel_drops = receive.kernel_drops.load(std::memory_order_relaxed);
  c.ring_overruns = receive.ring_overruns.load(std::memory_order_relaxed);
  c.receive_errors = receive.receive_errors.load(std::memory_order_relaxed);
  const StreamStats& s = decode.stream;
  c.packets_accepted = s.accepted;
  c.duplicate_packets = s.duplicates;
  c.outlier_packets = s.outliers;
  c.rejects = s.rejects;
  c.packets_rejected = s.rejected();
  c.sequence_gaps = decode.sequence.gaps;
  c.sequence_lost = decode.sequence.lost;
  c.sequence_duplicates = decode.sequence.duplicates;
  c.sequence_reordered = decode.sequence.reordered;
  c.sequence_resets = decode.sequence.resets;
  c.azimuth_gaps = s.azimuth_gaps;
  c.static_timestamp_packets = s.static_timestamps;
  c.backward_timestamp_packets = s.backward_timestamps;
  c.timestamp_jump_packets = s.timestamp_jumps;
  c.invalid_time_packets = s.bad_date + s.bad_microseconds;
  c.high_temperature_packets = s.high_temperature;
  c.return_mode_changes = s.return_mode_changes;
  c.points = s.points;
  c.filtered_points = s.filtered.by_reason;
  c.points_dropped_frame_full = decode.frames.points_dropped_full;
  c.frames_complete = decode.frames.frames_complete;
  c.frames_partial = decode.frames.frames_partial;
  c.frames_dropped_no_arena = decode.frames.frames_dropped;
  c.frames_decimated = decode.frames_decimated;
  c.frames_fragment = decode.frames_fragment;
  c.frames_written = sources.frames.frames_written();
  c.pcap_packets_written = sources.pcap.packets_written();
  c.pcap_packets_not_recorded = decode.raw_packets_dropped;
  c.pcap_packets_not_written = sources.pcap.packets_not_written();
  c.pcap_packets_lost = sources.pcap.packets_lost();
  c.packets_not_recorded =
      options_.pcap ? c.pcap_packets_not_recorded + c.pcap_packets_not_written + c.pcap_packets_lost
                    : 0;
  c.pcap_bytes_written = sources.pcap.bytes_written();
  count_mcap(sources.mcap);
  c.pcd_bytes_written = sources.frames.bytes_written();
  c.write_errors = sources.accounting.write_errors();
  c.bytes_not_written = sources.accounting.bytes_not_written();
  c.output_name_collisions = sources.accounting.name_collisions();
  c.files_removed_for_space = sources.files_removed_for_space;
  c.bytes_removed_for_space = sources.bytes_removed_for_space;
  c.receive_wakeups = receive.wakeups.load(std::memory_order_relaxed);
  c.decode_wakeups = sources.decode_wakeups;
  c.writer_wakeups = sources.writer_wakeups;
  h.frame_latency = sources.frames.latency();
  // The decode faults (issue 38): the sources on the port, the motor, what was lost in points.
  c.other_sensor_packets = receive.other_sensor.load(std::memory_order_relaxed);
  c.sensor_source_changes = receive.source_changes.load(std::memory_order_relaxed);
  c.standing_packets = s.standing;
  c.frameless_packets = s.frameless_packets;
  c.points_missing = decode.frames.packets_missing * kBlocks * kChannels;

  HealthGauges& g = h.gauges;
  g.uptime_seconds = static_cast<double>(now - start_monotonic_ns_) / 1e9;
  g.return_mode.assign(s.return_mode ? to_string(*s.return_mode) : std::string_view());
  g.high_temperature = s.last_high_temperature;
  g.rpm_tail = s.last_rpm;
  const double span_s = static_cast<double>(decode.monotonic_ns - decode_prev_.monotonic_ns) / 1e9;
  const auto d_az = s.measured_azimuth_cdeg - decode_prev_.stream.measured_azimuth_cdeg;
  const auto d_t = s.measured_time_ns - decode_prev_.stream.measured_time_ns;
  g.rpm_measured =
      d_t > 0 ? (static_cast<double>(d_az) / 36000.0) / (static_cast<double>(d_t) / 60e9) : 0.0;
  // Complete frames only: partial ones are cut by start, gaps and shutdown, not by rotation. The
  // final tick at shutdown can be a fraction of a second long (and sees the flushed partials),
  // so a window under half a second keeps the previous second's rate.
  const auto complete = decode.frames.frames_complete - decode_prev_.frames.frames_complete;
  if (span_s >= 0.5) g.frame_rate_hz = static_cast<double>(complete) / span_s;
  // By the sensor's clock, over a fifth of a second of it at least (else not known).
  const auto rate_t = s.rate_time_ns - decode_prev_.stream.rate_time_ns;
  g.packet_rate_hz = rate_t >= 200'000'000
                         ? static_cast<double>(s.rate_packets - decode_prev_.stream.rate_packets) *
                               1e9 / static_cast<double>(rate_t)
                         : 0.0;
  g.sensor_source = receive.sensor_source.load(std::memory_order_relaxed);
  g.other_sensor_source = receive.other_source.load(std::memory_order_relaxed);
  g.seconds_since_last_packet = sources.seconds_since_last_packet;
  g.sensor_clock_offset_known = decode.sensor_clock_offset_ns.has_value();
  g.sensor_clock_offset_seconds =
      static_cast<double>(decode.sensor_clock_offset_ns.value_or(0)) / 1e9;
  // Per second of the writer's own ticks, all three over the same window (the decoder's count is
  // read live, not from its snapshot). A final tick shorter than half a second keeps the last
  // rates.
  const double tick_s = static_cast<double>(now - last_tick_ns_) / 1e9;
  if (tick_s >= 0.5) {
    const HealthCounters& a = counters_a_second_ago_;
    g.receive_wakeups_per_second =
        static_cast<double>(c.receive_wakeups - a.receive_wakeups) / tick_s;
    g.decode_wakeups_per_second = static_cast<double>(c.decode_wakeups - a.decode_wakeups) / tick_s;
    g.writer_wakeups_per_second = static_cast<double>(c.writer_wakeups - a.writer_wakeups) / tick_s;
  }

  c.ptc_requests = sources.ptc_requests;
  c.ptc_errors = sources.ptc_errors;
  c.sensor_status_implausible = sources.sensor_status_implausible;
  fill_sensor_status(sources.sensor_status, now, g.sensor_status, options_.status_polled,
                     options_.status_interval_seconds);

  // The storage gauges: written bytes per output (kStorageOutputNames order) over the minute.
  write_rates_.sample(now, WriteRateWindow::Bytes{c.pcd_bytes_written, c.pcap_bytes_written,
                                                  c.mcap_bytes_written, jsonl_bytes_written_});
  fill_storage(write_rates_, sources.storage, g.storage);

  classify_health(
      c, previous_counters_,
      HealthExpectations{options_.expected_return_mode, options_.expected_rpm,
                         options_.max_sensor_clock_offset_seconds, options_.min_hours_left},
      sources.silent, sources.accounting.last_error(), g);
}

void HealthPublisher::remember(const DecodeSnapshot& decode, std::int64_t now) {
  if (now - last_tick_ns_ >= kNsPerSecond / 2) {  // the base of the next per-second rates
    counters_a_second_ago_ = health_.counters;
    last_tick_ns_ = now;
  }
  previous_counters_ = health_.counters;
  decode_prev_ = decode;
}

void HealthPublisher::write_first() {
  if (options_.prometheus) write_prometheus();
  if (options_.jsonl) jsonl_file_.open(jsonl_path_, OutputFile::Mode::kAppend);
}

void HealthPublisher::write() {
  bool prometheus_done = !options_.prometheus, jsonl_done = !options_.jsonl;
  // A few attempts: a piece of the reserve given back, a removed directory made again.
  for (int attempt = 0; attempt < 4; ++attempt) {
    const bool at_prometheus = !prometheus_done;
    try {
      if (!prometheus_done) {
        write_prometheus();
        prometheus_done = true;
      }
      if (!jsonl_done) {
        write_jsonl_line();
        jsonl_done = true;
      }
      return;
    } catch (const std::system_error& error) {
      const int code = error.code().value();
      if ((code == ENOSPC || code == EDQUOT) && space_.release_piece()) continue;
      const std::filesystem::path& dir =
          at_prometheus ? options_.prometheus_file.parent_path() : options_.health_dir;
      if (code == ENOENT && make_again_if_removed(dir)) continue;
      accounting_.write_failed(error, 0);
      return;
    } catch (const std::exception& error) {
      accounting_.write_failed(error, 0);
      return;
    }
  }
}

void HealthPublisher::write_prometheus() {
  render_prometheus(health_, prom_text_);
  write_file_replacing(prom_path_, prom_temporary_path_, prom_text_, prom_file_);
}

const std::string& HealthPublisher::json_line() {
  if (!json_text_current_) {
    render_json_line(health_, json_text_);
    json_text_current_ = true;
  }
  return json_text_;
}

void HealthPublisher::write_jsonl_line() {
  json_line();
  // Kept open between ticks (appending); reopened after rotation, a failed write, or when it is
  // no longer at its path (removed with its directory: lines written there would reach nobody).
  if (jsonl_file_.is_open() && !jsonl_file_.at_its_path()) jsonl_file_.close();
  if (!jsonl_file_.is_open()) jsonl_file_.open(jsonl_path_, OutputFile::Mode::kAppend);
  if (options_.jsonl_rotate_bytes != 0 &&
      jsonl_file_.size() + json_text_.size() > options_.jsonl_rotate_bytes) {
    jsonl_file_.close();
    rename_replacing(jsonl_path_, jsonl_rotated_path_);
    jsonl_file_.open(jsonl_path_, OutputFile::Mode::kAppend);
  }
  const std::uint64_t before = jsonl_file_.size();
  try {
    jsonl_file_.write(json_text_);
    jsonl_bytes_written_ += json_text_.size();
  } catch (...) {
    // A line cut short (a full disk) would glue itself to the next one: take it back.
    jsonl_file_.truncate(before);
    jsonl_file_.close();  // reopen next time (the file may have been removed)
    throw;
  }
}

void HealthPublisher::count_mcap(const McapRecorder& mcap) noexcept {
  json_text_current_ = false;
  HealthCounters& c = health_.counters;
  c.mcap_messages_written = mcap.messages_written();
  c.mcap_messages_not_written = mcap.messages_not_written();
  c.mcap_messages_not_recorded = mcap.messages_not_recorded();
  c.mcap_messages_lost = mcap.messages_lost();
  c.mcap_bytes_written = mcap.bytes_written();
}

}  // namespace pandarcap
