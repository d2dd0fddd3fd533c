#include "daemon/output/health_publisher.hpp"

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <filesystem>
#include <initializer_list>
#include <iterator>
#include <string_view>
#include <system_error>

#include "core/health/health_format.hpp"
#include "core/health/health_policy.hpp"
#include "core/sensors/sensor_models.hpp"
#include "core/units.hpp"
#include "daemon/allocation_counter.hpp"
#include "daemon/clocks.hpp"
#include "daemon/io/errors.hpp"
#include "daemon/io/file_creations.hpp"
#include "daemon/output/output_directories.hpp"
#include "daemon/output/standing_problems.hpp"

namespace pandarcap {
HealthPublisher::HealthPublisher(const WriterOptions& options, OutputAccounting& accounting,
                                 HealthRoom& space, FileFinisher& finisher)
    : options_(options), accounting_(accounting), space_(space), finisher_(finisher) {}

void HealthPublisher::prepare(std::int64_t start_monotonic_ns) {
  start_monotonic_ns_ = start_monotonic_ns;
  last_tick_ns_ = start_monotonic_ns;
  decode_prev_.monotonic_ns = start_monotonic_ns;
  prom_path_ = options_.prometheus_file.native();
  // Names of one length: the file object reusing its path buffer for both allocates nothing.
  assign_temporary_name(prom_temporary_paths_[0], prom_path_ + ".0");
  assign_temporary_name(prom_temporary_paths_[1], prom_path_ + ".1");
  jsonl_path_ = (options_.health_dir / "health.jsonl").native();
  jsonl_rotated_path_ = jsonl_path_ + ".1";
  // The probe of a health directory that failed: the name the start-up's writability probe uses.
  probe_path_ = (options_.health_dir / kProbeFileName).native();
  prom_probe_path_ = (options_.prometheus_file.parent_path() / kProbeFileName).native();
  use_fallback(0);
  for (const std::filesystem::path& dir : options_.health_fallback_dirs) {
    health_.gauges.health_fallback.directory.reserve(dir.native().size() + 1);
  }
  health_.gauges.health_fallback.error.reserve(1024);
  home_error_.reserve(1024);
  health_.sensor_identity = options_.sensor_identity;  // found at start-up, constant after
  prom_text_.reserve(64 * 1024);
  json_text_.reserve(8 * 1024);
  // The reasons are rebuilt in place every second; room for every problem at once (a write
  // error's message with its path included), so the first degraded second, long after the loop
  // is warm, does not allocate.
  health_.gauges.reason.reserve(8 * 1024);
  health_.gauges.sensor_status.implausible_reason.reserve(1024);
  health_.gauges.standing.reserve(2 * ReceiveCounters::kDamageTextBytes + 512);
  health_.gauges.last_invalid_time.reserve(32);  // "microseconds 4294967295"
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
  if (options_.sensor_name_from_model) {
    h.sensor = lower_case_name(decode.model);
  } else {
    h.sensor = options_.sensor_name;
  }
  model_ = decode.model;
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
                            sources.live->messages_dropped.load(std::memory_order_relaxed),
                            sources.live->listening.load(std::memory_order_relaxed)};
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
  // A datagram with no raw batch is missing from every recording of packets: the pcap's count,
  // and the MCAP's (count_mcap). The decoder keeps raw batches only for those.
  c.pcap_packets_not_recorded = options_.pcap ? decode.raw_packets_dropped : 0;
  mcap_packets_not_recorded_ =
      options_.mcap && options_.mcap_file.packets ? decode.raw_packets_dropped : 0;
  c.pcap_packets_not_written = sources.pcap.packets_not_written();
  c.pcap_packets_lost = sources.pcap.packets_lost();
  c.packets_not_recorded =
      options_.pcap ? c.pcap_packets_not_recorded + c.pcap_packets_not_written + c.pcap_packets_lost
                    : 0;
  c.pcap_bytes_written = sources.pcap.bytes_written();
  count_mcap(sources.mcap);
  c.pcd_bytes_written = sources.frames.bytes_written();
  const io::FileCreations& created = io::file_creations();
  c.files_created = created.files.load(std::memory_order_relaxed);
  c.file_create_cpu_us = created.cpu_ns.load(std::memory_order_relaxed) / 1000;
  c.write_errors = sources.accounting.write_errors();
  c.bytes_not_written = sources.accounting.bytes_not_written();
  c.output_name_collisions = sources.accounting.name_collisions();
  c.files_removed_for_space = sources.files_removed_for_space;
  c.bytes_removed_for_space = sources.bytes_removed_for_space;
  c.files_removed_before_upload = sources.storage.files_removed_before_upload;
  c.bytes_removed_before_upload = sources.storage.bytes_removed_before_upload;
  c.receive_wakeups = receive.wakeups.load(std::memory_order_relaxed);
  c.decode_wakeups = sources.decode_wakeups;
  c.writer_wakeups = sources.writer_wakeups;
  h.frame_latency = sources.frames.latency();
  // The decode faults (issue 38): the sources on the port, the motor, what was lost in points.
  c.other_sensor_packets = receive.other_sensor.load(std::memory_order_relaxed);
  c.sensor_source_changes = receive.source_changes.load(std::memory_order_relaxed);
  c.standing_packets = s.standing;
  c.frameless_packets = s.frameless_packets;
  if (s.last_invalid_field != TimeField::kNone) {
    std::string& text = h.gauges.last_invalid_time;  // (in place: its room was reserved)
    text.clear();
    fmt::format_to(std::back_inserter(text), "{} {}", to_string(s.last_invalid_field),
                   s.last_invalid_value);
  }
  c.reversed_packets = s.reversed;
  c.stream_changes = s.stream_changes;
  // Channel slots of the model decoded (a 40P's 400 a packet, a Pandar64's 384, an XT32's 256).
  const std::uint64_t slots = with_model(decode.model, []<class M>(std::type_identity<M>) {
    return static_cast<std::uint64_t>(M::kBlocks * M::kChannels);
  });
  c.points_missing = packets_missing(s, decode.sequence, decode.frames) * slots;

  HealthGauges& g = h.gauges;
  g.uptime_seconds = static_cast<double>(now - start_monotonic_ns_) / 1e9;
  g.return_mode.assign(s.return_mode ? to_string(*s.return_mode) : std::string_view());
  g.high_temperature = s.last_high_temperature;
  g.rpm_tail = s.last_rpm;
  const double span_s = static_cast<double>(decode.monotonic_ns - decode_prev_.monotonic_ns) / 1e9;
  const auto d_az = s.measured_azimuth_cdeg - decode_prev_.stream.measured_azimuth_cdeg;
  const auto d_t = s.measured_time_ns - decode_prev_.stream.measured_time_ns;
  // Packets that did not turn (a motor standing) measure 0; no packet in the window measures
  // nothing, and the last measurement stands (a final record just after the stream ended).
  if (d_t > 0) {
    g.rpm_measured = (static_cast<double>(d_az) / 36000.0) / (static_cast<double>(d_t) / 60e9);
  } else if (s.accepted > decode_prev_.stream.accepted) {
    g.rpm_measured = 0.0;
  }
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

  describe_standing_problems(receive, sources.live, g.standing);
  silence_ = sources.silence;
  reclassify();
}

void HealthPublisher::reclassify() {
  HealthCounters& c = health_.counters;
  c.write_errors = accounting_.write_errors();
  c.bytes_not_written = accounting_.bytes_not_written();
  classify_health(
      c, previous_counters_,
      HealthExpectations{options_.expected_return_mode, options_.expected_rpm,
                         options_.max_sensor_clock_offset_seconds, options_.min_hours_left, model_,
                         options_.calibration_channels, options_.inventory_lasers},
      silence_, accounting_.last_error(), health_.gauges);
  json_text_current_ = false;
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
  if (options_.prometheus) {
    render_prometheus(health_, prom_text_);
    write_file_durably(prom_path_, prom_text_);
  }
  if (options_.jsonl) {
    jsonl_file_.open(jsonl_path_, OutputFile::Mode::kAppend);
    jsonl_directory_synced_ = false;
  }
}

void HealthPublisher::write(std::int64_t now) {
  if (health_.gauges.health_fallback.active) {
    // The record says "fallback"; the health directory gets the next one once a probe file goes
    // in again (a read-only disk remounted, a subvolume made writable).
    if (!probe_home()) {
      write_fallback(now);
      return;
    }
    leave_fallback();
  } else if (!home_error_.empty()) {
    enter_fallback(now);  // the finisher could not sync or rename the last one
    return;
  }
  if (!write_home(now)) enter_fallback(now);
}

bool HealthPublisher::write_home(std::int64_t now) {
  bool prometheus_done = !options_.prometheus, jsonl_done = !options_.jsonl;
  // A few attempts: a piece of the reserve given back, a removed directory made again.
  for (int attempt = 0; attempt < 4; ++attempt) {
    const bool at_prometheus = !prometheus_done;
    try {
      if (!prometheus_done) {
        write_prometheus(now);
        prometheus_done = true;
      }
      if (!jsonl_done) {
        append_jsonl(jsonl_file_, jsonl_path_, jsonl_rotated_path_);
        jsonl_done = true;
      }
      return true;
    } catch (const std::system_error& error) {
      const int code = error.code().value();
      if ((code == ENOSPC || code == EDQUOT) && space_.release_piece()) continue;
      const std::filesystem::path& dir =
          at_prometheus ? options_.prometheus_file.parent_path() : options_.health_dir;
      if (code == ENOENT && make_again_if_removed(dir)) continue;
      accounting_.write_failed(error, 0);
      home_error_.assign(error.what());
      return false;
    } catch (const std::exception& error) {
      accounting_.write_failed(error, 0);
      home_error_.assign(error.what());
      return false;
    }
  }
  return true;  // still short of space after every piece: counted above, nothing else is wrong
}

void HealthPublisher::write_prometheus(std::int64_t now) {
  // A temporary name the finisher is not holding. Both held: the finisher has not synced the last
  // two yet (a slow disk); this one is skipped, and after 2 s the disk is failing them.
  const std::size_t slot = prom_pending_[0] ? 1 : 0;
  if (prom_pending_[slot]) {
    const std::int64_t oldest = std::min(prom_submitted_ns_[0], prom_submitted_ns_[1]);
    if (now - oldest < 2 * kNsPerSecond) return;
    io::throw_error(ETIMEDOUT, "no sync of the health file for 2 s:", prom_path_);
  }
  const std::string& temporary = prom_temporary_paths_[slot];
  render_prometheus(health_, prom_text_);
  try {
    prom_file_.open(temporary, OutputFile::Mode::kCreate);
    prom_file_.write(prom_text_);
    prom_file_.close();
  } catch (...) {
    ::unlink(temporary.c_str());
    throw;
  }
  FinishJob& job = finisher_.take();
  job.kind = FinishJob::Kind::kReplace;
  job.owner = FinishOwner::kHealth;
  job.from.assign(temporary);
  job.to.assign(prom_path_);
  job.remove_on_failure = true;
  job.items = slot;
  finisher_.submit(job);
  // In order: the finisher renames them as they were submitted, so the newest replaces the last.
  prom_pending_[slot] = true;
  prom_submitted_ns_[slot] = now;
}

void HealthPublisher::sync_jsonl() {
  if (!options_.jsonl || !jsonl_file_.is_open() || health_.gauges.health_fallback.active) return;
  finisher_.sync(FinishOwner::kHealth, jsonl_path_, jsonl_directory_synced_);
}

void HealthPublisher::finished(const FinishJob& job) {
  if (job.kind == FinishJob::Kind::kReplace) prom_pending_[job.items] = false;
  if (!job.failed) return;
  // health.jsonl gone (its directory removed): reopened and made again at the next write.
  if (job.kind == FinishJob::Kind::kSync && job.error_code == ENOENT) return;
  accounting_.write_failed(job.error_text(), 0);
  home_error_.assign(job.error_text());
}

bool HealthPublisher::probe_home() {
  for (const std::string* probe : {&probe_path_, &prom_probe_path_}) {
    if (probe == &probe_path_ ? !options_.jsonl : !options_.prometheus) continue;
    try {
      probe_file_.open(*probe, OutputFile::Mode::kCreate);
      probe_file_.write(std::string_view("1"));
      probe_file_.close();
      ::unlink(probe->c_str());
    } catch (const std::exception& error) {
      ::unlink(probe->c_str());
      // Still failing: counted (the health files were not written home this second).
      accounting_.write_failed(error, 0);
      health_.gauges.health_fallback.error.assign(error.what());
      return false;
    }
  }
  return true;
}

void HealthPublisher::enter_fallback(std::int64_t now) {
  HealthFallbackGauges& fallback = health_.gauges.health_fallback;
  fallback.active = true;
  use_fallback(0);
  fallback.error.assign(home_error_);
  home_error_.clear();
  jsonl_file_.close();  // reopened, and checked, when home again
  fallback_logged_ns_ = -1;
  reclassify();
  write_fallback(now);
}

void HealthPublisher::use_fallback(std::size_t index) {
  fallback_index_ = index;
  if (index >= options_.health_fallback_dirs.size()) {
    health_.gauges.health_fallback.directory.clear();  // none takes them
    return;
  }
  const std::filesystem::path& dir = options_.health_fallback_dirs[index];
  fallback_prom_path_ = (dir / options_.prometheus_file.filename()).native();
  assign_temporary_name(fallback_prom_temporary_path_, fallback_prom_path_);
  fallback_jsonl_path_ = (dir / "health.jsonl").native();
  fallback_jsonl_rotated_path_ = fallback_jsonl_path_ + ".1";
  fallback_prom_file_.close();
  fallback_jsonl_file_.close();
  if (health_.gauges.health_fallback.active)
    health_.gauges.health_fallback.directory = dir.native();
}

bool HealthPublisher::write_fallback_files() noexcept {
  const std::filesystem::path& dir = options_.health_fallback_dirs[fallback_index_];
  for (int attempt = 0; attempt < 2; ++attempt) {
    try {
      if (options_.prometheus) {
        render_prometheus(health_, prom_text_);
        write_file_replacing(fallback_prom_path_, fallback_prom_temporary_path_, prom_text_,
                             fallback_prom_file_);
      }
      if (options_.jsonl) {
        append_jsonl(fallback_jsonl_file_, fallback_jsonl_path_, fallback_jsonl_rotated_path_);
      }
      return true;
    } catch (const std::exception& error) {
      // Its directory is made at the first need (a tmpfs under /run starts empty).
      std::error_code ignored;
      if (attempt == 0 && std::filesystem::create_directories(dir, ignored)) continue;
      fallback_error_ = fmt::format("{}: {}", dir.string(), error.what());
    }
  }
  return false;
}

void HealthPublisher::write_fallback(std::int64_t now) {
  HealthFallbackGauges& fallback = health_.gauges.health_fallback;
  const bool log = fallback_logged_ns_ < 0 || now - fallback_logged_ns_ >= 10 * kNsPerSecond;
  if (log) fallback_logged_ns_ = now;
  // The directory in use, else the next of them that takes the files: the record is decided
  // again for each, so that it names where it is.
  for (std::size_t tried = 0; fallback_index_ < options_.health_fallback_dirs.size(); ++tried) {
    if (write_fallback_files()) {
      if (log) {
        spdlog::error("health: {}; writing the health files to {} until {} takes them again",
                      fallback.error, fallback.directory, options_.health_dir.string());
      }
      return;
    }
    spdlog::error("health: {} cannot take the health files either ({})",
                  options_.health_fallback_dirs[fallback_index_].string(), fallback_error_);
    use_fallback(fallback_index_ + 1);
    if (fallback_index_ < options_.health_fallback_dirs.size()) reclassify();
  }
  // None takes them: said where it still can be (the journal, STATUS=, the exit summary).
  if (!fallback.directory.empty() || fallback.error.find(fallback_error_) == std::string::npos) {
    fallback.directory.clear();
    fallback.error += "; and no fallback directory either (";
    fallback.error += fallback_error_;
    fallback.error += ')';
    reclassify();
  }
  if (log) spdlog::error("health: cannot be written anywhere: {}", fallback.error);
}

void HealthPublisher::leave_fallback() {
  HealthFallbackGauges& fallback = health_.gauges.health_fallback;
  fallback.active = false;
  fallback.directory.clear();
  fallback.error.clear();
  fallback_jsonl_file_.close();
  ::unlink(fallback_prom_path_.c_str());  // no monitor keeps reading a frozen copy
  use_fallback(0);
  reclassify();
  spdlog::info("health: {} takes writes again; the health files are back there ({} removed)",
               options_.health_dir.string(), fallback_prom_path_);
}

const std::string& HealthPublisher::json_line() {
  if (!json_text_current_) {
    render_json_line(health_, json_text_);
    json_text_current_ = true;
  }
  return json_text_;
}

void HealthPublisher::append_jsonl(OutputFile& file, const std::string& path,
                                   const std::string& rotated) {
  json_line();
  // Kept open between ticks (appending); reopened after rotation, a failed write, or when it is
  // no longer at its path (removed with its directory: lines written there would reach nobody).
  if (file.is_open() && !file.at_its_path()) file.close();
  if (!file.is_open()) {
    file.open(path, OutputFile::Mode::kAppend);
    if (&file == &jsonl_file_) jsonl_directory_synced_ = false;
  }
  if (options_.jsonl_rotate_bytes != 0 &&
      file.size() + json_text_.size() > options_.jsonl_rotate_bytes) {
    file.close();
    rename_replacing(path, rotated);
    file.open(path, OutputFile::Mode::kAppend);
    if (&file == &jsonl_file_) jsonl_directory_synced_ = false;
  }
  const std::uint64_t before = file.size();
  try {
    file.write(json_text_);
    jsonl_bytes_written_ += json_text_.size();
  } catch (...) {
    // A line cut short (a full disk) would glue itself to the next one: take it back.
    file.truncate(before);
    file.close();  // reopen next time (the file may have been removed)
    throw;
  }
}

void HealthPublisher::count_mcap(const McapRecorder& mcap) noexcept {
  json_text_current_ = false;
  HealthCounters& c = health_.counters;
  c.mcap_messages_written = mcap.messages_written();
  c.mcap_messages_not_written = mcap.messages_not_written();
  c.mcap_messages_not_recorded = mcap.messages_not_recorded() + mcap_packets_not_recorded_;
  c.mcap_chunks_uncompressed = mcap.chunks_uncompressed();
  c.mcap_messages_lost = mcap.messages_lost();
  c.mcap_bytes_written = mcap.bytes_written();
}

}  // namespace pandarcap
