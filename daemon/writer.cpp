#include "daemon/writer.hpp"

#include <arpa/inet.h>
#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <fstream>
#include <optional>
#include <stdexcept>
#include <string_view>
#include <system_error>
#include <vector>

#include "core/health_format.hpp"
#include "core/pcd.hpp"
#include "core/text_file.hpp"
#include "daemon/allocation_counter.hpp"
#include "daemon/clocks.hpp"
#include "daemon/io/file_output.hpp"
#include "daemon/pcap/pcap_recovery.hpp"

namespace pandarcap {
namespace {

constexpr std::int64_t kSecondNs = 1'000'000'000;
constexpr std::size_t kPcdChunkPoints = 4096;

// The number in one of our file names: the `field`-th '_'-separated field after `prefix`
// ("frame_000123_...pcd": field 0; "pandarcap_20261122T120000Z_0007...pcap": field 1). Nothing
// when the name is not one of ours.
std::optional<std::uint64_t> number_in_name(std::string_view name, std::string_view prefix,
                                            std::string_view suffix, int field) {
  if (!name.starts_with(prefix) || !name.ends_with(suffix)) return std::nullopt;
  name.remove_prefix(prefix.size());
  for (int i = 0; i < field; ++i) {
    const std::size_t underscore = name.find('_');
    if (underscore == std::string_view::npos) return std::nullopt;
    name.remove_prefix(underscore + 1);
  }
  std::uint64_t number = 0;
  std::size_t digits = 0;
  while (digits < name.size() && name[digits] >= '0' && name[digits] <= '9') {
    if (digits == 18) return std::nullopt;  // not one of ours, and beyond what a count reaches
    number = number * 10 + static_cast<std::uint64_t>(name[digits] - '0');
    ++digits;
  }
  if (digits == 0 || (digits < name.size() && name[digits] != '_' && name[digits] != '.')) {
    return std::nullopt;
  }
  return number;
}

// Proves `dir` takes a new file (permissions, a read-only mount, a full inode table) by creating
// and removing one: READY=1 promises writable outputs. Throws std::system_error.
void probe_writable(const std::filesystem::path& dir) {
  const std::filesystem::path probe = dir / ".pandarcapd-probe.tmp";
  OutputFile file(probe, OutputFile::Mode::kCreate);
  file.close();
  ::unlink(probe.c_str());
}

}  // namespace

Writer::Writer(const WriterOptions& options, DecodeWorker::WriterQueue& from_decoder,
               DecodeWorker::ArenaQueue& arenas_back, DecodeWorker::RawQueue& raw_back,
               const ReceiveCounters& receive, const LiveClock& live)
    : options_(options),
      from_decoder_(from_decoder),
      arenas_back_(arenas_back),
      raw_back_(raw_back),
      receive_(receive),
      live_(live),
      frames_dir_(options.output_dir / "frames"),
      raw_dir_(options.output_dir / "raw"),
      pcd_buffer_(kPcdChunkPoints * kPcdPointBytes),
      pcap_buffer_(kPcapStdioBufferBytes) {}

Writer::~Writer() = default;

void Writer::prepare() {
  start_monotonic_ns_ = monotonic_ns();
  last_tick_ns_ = start_monotonic_ns_;
  decode_.monotonic_ns = decode_prev_.monotonic_ns = start_monotonic_ns_;
  std::filesystem::create_directories(options_.health_dir);
  if (options_.prometheus && options_.prometheus_file.has_parent_path()) {
    std::filesystem::create_directories(options_.prometheus_file.parent_path());
  }
  if (options_.frames) {
    std::filesystem::create_directories(frames_dir_);
    probe_writable(frames_dir_);
  }
  if (options_.pcap) std::filesystem::create_directories(raw_dir_);
  prom_path_ = options_.prometheus_file.native();
  assign_temporary_name(prom_temporary_path_, prom_path_);
  jsonl_path_ = (options_.health_dir / "health.jsonl").native();
  jsonl_rotated_path_ = jsonl_path_ + ".1";
  finish_leftovers();
  adopt_earlier_files();
  if (options_.pcap) save_calibration();
  prom_text_.reserve(64 * 1024);
  json_text_.reserve(8 * 1024);
  frame_path_.reserve(4096);
  frame_temporary_path_.reserve(4096);
  pcd_header_.reserve(1024);
  // Proves the health directories are writable before the daemon reports ready.
  build_health(start_monotonic_ns_);
  if (options_.prometheus) {
    render_prometheus(health_, prom_text_);
    write_file_replacing(prom_path_, prom_temporary_path_, prom_text_, health_file_);
  }
  if (options_.jsonl) jsonl_file_.open(jsonl_path_, OutputFile::Mode::kAppend);
}

void Writer::finish_leftovers() {
  namespace fs = std::filesystem;
  std::error_code ec;
  // Recordings left open: cut back to their last whole record and given their final name.
  if (options_.pcap) {
    for (const auto& entry : fs::directory_iterator(raw_dir_, ec)) {
      const std::string part = entry.path().native();
      if (!part.ends_with(".pcap.part")) continue;
      // Never followed: a link (or a device, a FIFO) here points at a file that is not ours to
      // cut, wherever it leads.
      if (entry.is_symlink(ec) || !entry.is_regular_file(ec)) {
        spdlog::warn("{}: not a regular file; left as it is", part);
        continue;
      }
      try {
        const PcapRecovery recovered = finish_interrupted_pcap(part);
        if (!recovered.ours) {
          spdlog::warn("{}: not a recording of ours; left as it is", part);
          continue;
        }
        if (recovered.records == 0) {
          fs::remove(part);
          spdlog::warn("{}: left by an interrupted run with no whole record; removed", part);
          continue;
        }
        std::string finished = part.substr(0, part.size() - 5);  // without ".part"
        put_in_place(part, finished);
        spdlog::warn(
            "{}: left by an interrupted run; finished as {} ({} whole records, {} bytes of "
            "a cut record removed)",
            part, fs::path(finished).filename().string(), recovered.records, recovered.cut_bytes);
      } catch (const std::exception& error) {
        spdlog::error("{}: cannot finish a recording left by an interrupted run: {}", part,
                      error.what());
      }
    }
  }
  // Temporary files (".NAME.tmp") hold nothing that was ever complete: removed.
  const auto remove_temporaries = [&](const fs::path& dir) {
    for (const auto& entry : fs::directory_iterator(dir, ec)) {
      const std::string name = entry.path().filename().native();
      if (name.size() > 5 && name.front() == '.' && name.ends_with(".tmp") &&
          entry.is_regular_file(ec)) {
        fs::remove(entry.path(), ec);
        spdlog::info("{}: temporary file of an interrupted run removed", entry.path().string());
      }
    }
  };
  if (options_.frames) remove_temporaries(frames_dir_);
  if (options_.pcap) remove_temporaries(raw_dir_);
  // The health directory may be shared (node_exporter's): only our own temporary name.
  if (options_.prometheus && fs::remove(prom_temporary_path_, ec)) {
    spdlog::info("{}: temporary file of an interrupted run removed", prom_temporary_path_);
  }
  // A health line cut short (a crash mid-append, a full disk) is dropped: readers then never see
  // two lines glued together.
  if (options_.jsonl) {
    std::ifstream in(jsonl_path_, std::ios::binary | std::ios::ate);
    const std::streamoff size = in ? static_cast<std::streamoff>(in.tellg()) : 0;
    if (size > 0) {
      std::streamoff keep = size;
      char c = 0;
      while (keep > 0) {
        in.seekg(keep - 1);
        in.get(c);
        if (c == '\n') break;
        --keep;
      }
      if (keep < size) {
        fs::resize_file(jsonl_path_, static_cast<std::uintmax_t>(keep), ec);
        spdlog::warn("{}: a line cut short by an interrupted run removed ({} bytes)", jsonl_path_,
                     size - keep);
      }
    }
  }
}

void Writer::adopt_earlier_files() {
  namespace fs = std::filesystem;
  struct Found {
    std::uint64_t number;
    std::string name;
    fs::path path;
    std::uint64_t bytes;
  };
  // Our files in `dir`, oldest (lowest number) first; a link or anything not a regular file is
  // not ours.
  const auto scan = [](const fs::path& dir, std::string_view prefix, std::string_view suffix,
                       int field) {
    std::vector<Found> found;
    std::error_code ec;
    for (const auto& entry : fs::directory_iterator(dir, ec)) {
      const std::string name = entry.path().filename().native();
      const auto number = number_in_name(name, prefix, suffix, field);
      if (!number || entry.is_symlink(ec) || !entry.is_regular_file(ec)) continue;
      const auto bytes = entry.file_size(ec);
      found.push_back({*number, name, entry.path(), ec ? 0 : bytes});
    }
    std::sort(found.begin(), found.end(), [](const Found& a, const Found& b) {
      return a.number != b.number ? a.number < b.number : a.name < b.name;
    });
    return found;
  };
  const auto adopt = [&](const std::vector<Found>& found, auto& list, std::uint64_t max_files,
                         std::uint64_t max_bytes, const char* what, const fs::path& dir) {
    for (const Found& f : found)
      list.emplace_back(f.path, f.bytes);
    const std::size_t before = list.size();
    enforce_retention(list, max_files, max_bytes);
    if (!found.empty()) {
      spdlog::info("{}: {} {} of earlier runs{}", dir.string(), found.size(), what,
                   before > list.size() && (max_files != 0 || max_bytes != 0)
                       ? fmt::format("; retention removed the oldest {}", before - list.size())
                       : std::string());
    }
  };
  if (options_.frames) {
    const auto found = scan(frames_dir_, "frame_", ".pcd", 0);
    if (!found.empty()) frame_number_base_ = found.back().number + 1;
    adopt(found, frame_files_, options_.frames_max_files, options_.frames_max_bytes, "frames",
          frames_dir_);
  }
  if (options_.pcap) {
    const auto found = scan(raw_dir_, "pandarcap_", ".pcap", 1);
    if (!found.empty()) pcap_index_ = found.back().number + 1;
    adopt(found, pcap_files_, options_.pcap_max_files, options_.pcap_max_bytes, "recordings",
          raw_dir_);
  }
}

void Writer::save_calibration() {
  // The angles the recordings are decoded with travel with them: raw/calibration.csv is this
  // run's. When an earlier run used other angles, its table is kept, not replaced, as
  // calibration_before_<N>.csv: recordings numbered below N (since the previous such file) were
  // made with it.
  const std::filesystem::path current = raw_dir_ / "calibration.csv";
  const TextFile earlier = read_text_file(current.string());
  if (earlier.status == TextFile::Status::kOk && earlier.text != options_.calibration_csv) {
    std::string kept =
        (raw_dir_ / fmt::format("calibration_before_{:04}.csv", pcap_index_)).native();
    put_in_place(current.native(), kept);
    spdlog::info("{}: the calibration of earlier recordings differs from this run's; kept as {}",
                 current.string(), std::filesystem::path(kept).filename().string());
  }
  write_file_replacing(current, options_.calibration_csv);
}

void Writer::put_in_place(const std::string& from, std::string& to) {
  if (!place_without_replacing(from, to)) return;
  ++name_collisions_;
  spdlog::warn("{}: a file of that name exists; kept as {} instead of replacing it", from, to);
}

void Writer::log_fragments(std::int64_t now) {
  const std::uint64_t fragments = health_.counters.frames_fragment;
  if (fragments == fragments_logged_) return;
  if (last_fragment_log_ns_ >= 0 && now - last_fragment_log_ns_ < 10 * kSecondNs) return;
  spdlog::info(
      "{} frame fragment{} not written (partial frames under output.frames_min_fraction of a "
      "revolution; {} since start)",
      fragments - fragments_logged_, fragments - fragments_logged_ == 1 ? "" : "s", fragments);
  fragments_logged_ = fragments;
  last_fragment_log_ns_ = now;
}

void Writer::write_failed(const std::exception& error, std::uint64_t bytes) {
  ++write_errors_;
  bytes_not_written_ += bytes;
  last_error_ = error.what();
  const std::int64_t now = monotonic_ns();
  if (last_error_log_ns_ < 0 || now - last_error_log_ns_ >= 10 * kSecondNs) {
    spdlog::error("write failed: {} ({} write errors so far)", last_error_, write_errors_);
    last_error_log_ns_ = now;
  }
}

void Writer::enforce_retention(std::deque<std::pair<std::filesystem::path, std::uint64_t>>& files,
                               std::uint64_t max_files, std::uint64_t max_bytes) {
  if (max_files == 0 && max_bytes == 0) {
    files.clear();  // nothing to enforce: do not keep a list that grows forever
    return;
  }
  std::uint64_t total = 0;
  for (const auto& file : files)
    total += file.second;
  while (!files.empty() &&
         ((max_files != 0 && files.size() > max_files) || (max_bytes != 0 && total > max_bytes))) {
    std::error_code ignored;
    std::filesystem::remove(files.front().first, ignored);
    total -= files.front().second;
    files.pop_front();
  }
}

void Writer::write_frame(FrameArena& arena) {
  const Frame& frame = arena.frame;
  const std::span<const Point> points = frame.used();
  pcd_header_.clear();
  append_pcd_header(pcd_header_, points.size());
  const std::uint64_t expected = pcd_header_.size() + points.size() * kPcdPointBytes;
  // frames/frame_000123_20261122T120000.123Z[_partial].pcd, written as frames/.<name>.tmp.
  frame_path_.assign(frames_dir_.native());
  fmt::format_to(std::back_inserter(frame_path_), "/frame_{:06}_",
                 frame_number_base_ + frame.info.sequence);
  append_utc_file_stamp(frame_path_, frame.info.start_ns, true);
  frame_path_ += frame.info.partial ? "_partial.pcd" : ".pcd";
  assign_temporary_name(frame_temporary_path_, frame_path_);
  try {
    frame_file_.open(frame_temporary_path_, OutputFile::Mode::kCreate);
    frame_file_.write(pcd_header_);
    for (std::size_t i = 0; i < points.size(); i += kPcdChunkPoints) {
      const auto chunk = points.subspan(i, std::min(kPcdChunkPoints, points.size() - i));
      const std::size_t n = encode_pcd_points(chunk, pcd_buffer_);
      frame_file_.write(std::span<const std::uint8_t>(pcd_buffer_.data(), n));
    }
    frame_file_.close();
    put_in_place(frame_temporary_path_, frame_path_);
    ++frames_written_;
    pcd_bytes_ += expected;
    if (arena.completed_receive_ns > 0) {
      frame_latency_.record(realtime_ns() - arena.completed_receive_ns);
    }
    // Retention keeps a list of names (one allocation per file); without it, no list.
    if (options_.frames_max_files != 0 || options_.frames_max_bytes != 0) {
      frame_files_.emplace_back(frame_path_, expected);
      enforce_retention(frame_files_, options_.frames_max_files, options_.frames_max_bytes);
    }
  } catch (const std::exception& error) {
    ::unlink(frame_temporary_path_.c_str());
    write_failed(error, expected);
  }
}

void Writer::open_pcap(std::int64_t first_packet_ns) {
  pcap_final_path_ = (raw_dir_ / fmt::format("pandarcap_{}_{:04}.pcap",
                                             utc_file_stamp(first_packet_ns, false), pcap_index_++))
                         .native();
  const std::filesystem::path part = pcap_final_path_ + ".part";
  try {
    pcap_ = std::make_unique<PcapWriter>(part.string(), pcap_buffer_);
  } catch (...) {
    // Created but not even its header written (a full disk): not left behind, one per attempt.
    std::error_code ignored;
    std::filesystem::remove(part, ignored);
    throw;
  }
  pcap_opened_monotonic_ns_ = monotonic_ns();
}

void Writer::close_pcap() {
  if (!pcap_) return;
  try {
    // Flushed first: a failing flush leaves the file to be cut back to whole records; once it
    // succeeded, fclose has nothing left to write.
    pcap_->flush();
    pcap_->close();
  } catch (const std::exception& error) {
    abandon_pcap(error, 0);
    return;
  }
  finish_pcap_file();
}

void Writer::abandon_pcap(const std::exception& error, std::uint64_t failed_bytes) {
  // The records buffered since the last good flush never reached the file whole: they are taken
  // back from the recorded count (which no health record has reported yet: every tick flushes
  // first) and counted as not written, with the record being written when it failed.
  const PcapWriter::Dropped dropped = pcap_->abandon();
  pcap_packets_ -= dropped.records;
  pcap_packets_not_written_ += dropped.records;
  write_failed(error, dropped.bytes + failed_bytes);
  finish_pcap_file();
}

void Writer::finish_pcap_file() {
  const std::string part = pcap_->path();
  try {
    if (pcap_->flushed_records() == 0) {
      std::filesystem::remove(part);  // not even one record: nothing worth keeping
    } else {
      put_in_place(part, pcap_final_path_);
      pcap_bytes_closed_ += pcap_->flushed_bytes();
      pcap_files_.emplace_back(pcap_final_path_, pcap_->flushed_bytes());
      enforce_retention(pcap_files_, options_.pcap_max_files, options_.pcap_max_bytes);
    }
  } catch (const std::exception& error) {
    write_failed(error, 0);
  }
  pcap_.reset();
}

void Writer::write_raw(RawBatch& batch) {
  bool failed = false;  // the disk failed on this batch: the rest is not tried (counted)
  for (std::size_t i = 0; i < batch.size; ++i) {
    const RawPacket& packet = batch.packets[i];
    if (failed) {
      ++pcap_packets_not_written_;
      bytes_not_written_ += packet.length;
      continue;
    }
    try {
      if (pcap_ &&
          ((options_.pcap_rotate_bytes != 0 && pcap_->bytes() >= options_.pcap_rotate_bytes) ||
           (options_.pcap_rotate_seconds != 0 && monotonic_ns() - pcap_opened_monotonic_ns_ >=
                                                     options_.pcap_rotate_seconds * kSecondNs))) {
        close_pcap();
      }
      if (!pcap_) open_pcap(packet.receive_time_ns);
      pcap_->write(std::span<const std::uint8_t>(packet.payload, packet.length),
                   packet.original_length, packet.receive_time_ns,
                   Endpoint{ntohl(packet.source.sin_addr.s_addr), ntohs(packet.source.sin_port)},
                   options_.pcap_destination);
      ++pcap_packets_;
    } catch (const std::invalid_argument& error) {
      // This packet cannot be recorded (a time outside what pcap can hold); the file is fine.
      ++pcap_packets_not_written_;
      write_failed(error, packet.length);
    } catch (const std::exception& error) {
      // A failing file is cut back to its whole records and closed. The next batch starts a new
      // one (and fails again, counted, while the disk stays full): at most one attempt per
      // batch, not one per packet.
      ++pcap_packets_not_written_;
      if (pcap_) {
        abandon_pcap(error, packet.length);
      } else {
        write_failed(error, packet.length);  // the file could not even be created
      }
      failed = true;
    }
  }
  // Each batch reaches the file whole: a crash loses at most the batch being written.
  if (pcap_) {
    try {
      pcap_->flush();
    } catch (const std::exception& error) {
      abandon_pcap(error, 0);
    }
  }
}

void Writer::rotate_outputs() {
  spdlog::info("SIGHUP: closing {} and starting new recordings",
               pcap_ ? std::filesystem::path(pcap_final_path_).filename().string()
                     : std::string("no open pcap"));
  close_pcap();
}

void Writer::build_health(std::int64_t now) {
  // Filled in place: its strings keep their capacity from one second to the next.
  HealthSnapshot& h = health_;
  h.unix_time_ns = realtime_ns();
  h.sensor = options_.sensor_name;
  h.version = options_.version;
  h.decoder = options_.decoder;
  HealthCounters& c = h.counters;
  h.latency = decode_.latency;
  if (alloc::counting_available()) {
    h.hot_path_allocations = HotPathAllocations{alloc::hot_allocations(alloc::HotThread::kReceive),
                                                alloc::hot_allocations(alloc::HotThread::kDecode),
                                                alloc::hot_allocations(alloc::HotThread::kWriter)};
  }
  c.datagrams_received = receive_.datagrams.load(std::memory_order_relaxed);
  c.bytes_received = receive_.bytes.load(std::memory_order_relaxed);
  c.foreign_datagrams = receive_.foreign.load(std::memory_order_relaxed);
  c.truncated_datagrams = receive_.truncated.load(std::memory_order_relaxed);
  c.kernel_drops = receive_.kernel_drops.load(std::memory_order_relaxed);
  c.ring_overruns = receive_.ring_overruns.load(std::memory_order_relaxed);
  c.receive_errors = receive_.receive_errors.load(std::memory_order_relaxed);
  const StreamStats& s = decode_.stream;
  c.packets_accepted = s.accepted;
  c.rejects = s.rejects;
  c.packets_rejected = s.rejected();
  c.sequence_gaps = decode_.sequence.gaps;
  c.sequence_lost = decode_.sequence.lost;
  c.sequence_duplicates = decode_.sequence.duplicates;
  c.sequence_reordered = decode_.sequence.reordered;
  c.sequence_resets = decode_.sequence.resets;
  c.azimuth_gaps = s.azimuth_gaps;
  c.static_timestamp_packets = s.static_timestamps;
  c.backward_timestamp_packets = s.backward_timestamps;
  c.timestamp_jump_packets = s.timestamp_jumps;
  c.invalid_time_packets = s.bad_date + s.bad_microseconds;
  c.high_temperature_packets = s.high_temperature;
  c.return_mode_changes = s.return_mode_changes;
  c.points = s.points;
  c.filtered_points = s.filtered.by_reason;
  c.points_dropped_frame_full = decode_.frames.points_dropped_full;
  c.frames_complete = decode_.frames.frames_complete;
  c.frames_partial = decode_.frames.frames_partial;
  c.frames_dropped_no_arena = decode_.frames.frames_dropped;
  c.frames_decimated = decode_.frames_decimated;
  c.frames_fragment = decode_.frames_fragment;
  c.frames_written = frames_written_;
  c.pcap_packets_written = pcap_packets_;
  c.pcap_packets_not_recorded = decode_.raw_packets_dropped;
  c.pcap_packets_not_written = pcap_packets_not_written_;
  c.pcap_bytes_written = pcap_bytes_closed_ + (pcap_ ? pcap_->bytes() : 0);
  c.pcd_bytes_written = pcd_bytes_;
  c.write_errors = write_errors_;
  c.bytes_not_written = bytes_not_written_;
  c.output_name_collisions = name_collisions_;
  c.receive_wakeups = receive_.wakeups.load(std::memory_order_relaxed);
  c.decode_wakeups = decode_.wakeups;
  c.writer_wakeups = wakeups_;
  h.frame_latency = frame_latency_;

  HealthGauges& g = h.gauges;
  g.uptime_seconds = static_cast<double>(now - start_monotonic_ns_) / 1e9;
  g.return_mode.assign(s.return_mode ? to_string(*s.return_mode) : std::string_view());
  g.high_temperature = s.last_high_temperature;
  g.rpm_tail = s.last_rpm;
  const double span_s = static_cast<double>(decode_.monotonic_ns - decode_prev_.monotonic_ns) / 1e9;
  const auto d_az = s.measured_azimuth_cdeg - decode_prev_.stream.measured_azimuth_cdeg;
  const auto d_t = s.measured_time_ns - decode_prev_.stream.measured_time_ns;
  g.rpm_measured =
      d_t > 0 ? (static_cast<double>(d_az) / 36000.0) / (static_cast<double>(d_t) / 60e9) : 0.0;
  // Complete frames only: partial ones are cut by start, gaps and shutdown, not by rotation. The
  // final tick at shutdown can be a fraction of a second long (and sees the flushed partials),
  // so a window under half a second keeps the previous second's rate.
  const auto complete = decode_.frames.frames_complete - decode_prev_.frames.frames_complete;
  if (span_s >= 0.5) {
    g.frame_rate_hz = static_cast<double>(complete) / span_s;
    g.decode_wakeups_per_second =
        static_cast<double>(decode_.wakeups - decode_prev_.wakeups) / span_s;
  }
  g.seconds_since_last_packet = seconds_since_last_packet(now);
  // Per second of the writer's own ticks; the decoder's over the span of its last two snapshots
  // (they arrive about once a second, not in step with the ticks). A final tick shorter than
  // half a second keeps the last rates.
  const double tick_s = static_cast<double>(now - last_tick_ns_) / 1e9;
  if (tick_s >= 0.5) {
    const HealthCounters& a = counters_a_second_ago_;
    g.receive_wakeups_per_second =
        static_cast<double>(c.receive_wakeups - a.receive_wakeups) / tick_s;
    g.writer_wakeups_per_second = static_cast<double>(c.writer_wakeups - a.writer_wakeups) / tick_s;
  }

  // State: error > no_data > degraded > ok; the reason names what changed since the last tick.
  // The problems are written straight into the reason (cleared, its capacity kept), and the
  // reason is cut back to what the winning state says.
  const HealthCounters& p = previous_counters_;
  std::string& problems = g.reason;
  problems.clear();
  const auto problem = [&]<typename... Args>(fmt::format_string<Args...> format, Args&&... args) {
    if (!problems.empty()) problems += "; ";
    fmt::format_to(std::back_inserter(problems), format, std::forward<Args>(args)...);
  };
  const auto grew = [&](std::uint64_t now_value, std::uint64_t before, const char* what) {
    if (now_value > before) problem("{} {}", now_value - before, what);
  };
  if (c.write_errors > p.write_errors) {
    problem("{} write errors ({} bytes not written): {}", c.write_errors - p.write_errors,
            c.bytes_not_written - p.bytes_not_written, last_error_);
  }
  grew(c.kernel_drops, p.kernel_drops, "kernel drops");
  grew(c.ring_overruns, p.ring_overruns, "ring overruns");
  grew(c.frames_dropped_no_arena, p.frames_dropped_no_arena, "frames dropped (no free arena)");
  grew(c.pcap_packets_not_recorded, p.pcap_packets_not_recorded, "packets not recorded");
  grew(c.sequence_lost, p.sequence_lost, "packets lost (sequence)");
  grew(c.azimuth_gaps, p.azimuth_gaps, "azimuth gaps");
  grew(c.packets_rejected, p.packets_rejected, "packets rejected");
  grew(c.static_timestamp_packets, p.static_timestamp_packets, "static timestamps");
  grew(c.backward_timestamp_packets, p.backward_timestamp_packets, "timestamps going back");
  grew(c.timestamp_jump_packets, p.timestamp_jump_packets, "timestamp jumps");
  if (g.high_temperature) problem("sensor high-temperature flag set");
  if (options_.expected_return_mode != "any" && !g.return_mode.empty() &&
      g.return_mode != options_.expected_return_mode) {
    problem("return mode {} (expected {})", g.return_mode, options_.expected_return_mode);
  }
  if (g.seconds_since_last_packet >= 0 && g.rpm_tail > 0 &&
      std::abs(g.rpm_tail - options_.expected_rpm) > 0.1 * options_.expected_rpm) {
    problem("motor at {:.0f} RPM (expected {})", g.rpm_tail, options_.expected_rpm);
  }
  // Failing writes degrade (capture goes on, and every byte not written is counted; they lead
  // the reason). A failing socket is an error: the daemon is not capturing.
  if (c.receive_errors > p.receive_errors) {
    g.state = HealthState::kError;
    g.reason.clear();
    fmt::format_to(std::back_inserter(g.reason), "{} receive errors: the socket is failing",
                   c.receive_errors - p.receive_errors);
  } else if (silent(now)) {
    g.state = HealthState::kNoData;
    g.reason.clear();
    if (g.seconds_since_last_packet < 0) {
      g.reason += "no packet received yet";
    } else {
      fmt::format_to(std::back_inserter(g.reason), "no packet for {:.1f} s",
                     g.seconds_since_last_packet);
    }
  } else if (!problems.empty()) {
    g.state = HealthState::kDegraded;
  } else {
    g.state = HealthState::kOk;
  }
}

double Writer::seconds_since_last_packet(std::int64_t now) const noexcept {
  const std::int64_t last = live_.last_packet_monotonic_ns.load(std::memory_order_relaxed);
  return last == 0 ? -1.0 : static_cast<double>(std::max<std::int64_t>(now - last, 0)) / 1e9;
}

bool Writer::silent(std::int64_t now) const noexcept {
  const double since = seconds_since_last_packet(now);
  return since < 0 || since > options_.no_data_timeout_seconds;
}

void Writer::write_health(bool final) {
  const std::int64_t now = monotonic_ns();
  if (pcap_) {
    try {
      pcap_->flush();  // the recording on disk is at most a second behind
    } catch (const std::exception& error) {
      abandon_pcap(error, 0);
    }
  }
  build_health(now);
  if (now - last_tick_ns_ >= kSecondNs / 2) {  // the base of the next per-second rates
    counters_a_second_ago_ = health_.counters;
    last_tick_ns_ = now;
  }
  log_fragments(now);
  reported_silent_ = silent(now);
  previous_counters_ = health_.counters;
  decode_prev_ = decode_;
  try {
    if (options_.prometheus) {
      render_prometheus(health_, prom_text_);
      write_file_replacing(prom_path_, prom_temporary_path_, prom_text_, health_file_);
    }
    if (options_.jsonl) {
      render_json_line(health_, json_text_);
      // Kept open between ticks (appending); reopened after rotation or a failed write.
      if (!jsonl_file_.is_open()) jsonl_file_.open(jsonl_path_, OutputFile::Mode::kAppend);
      if (options_.jsonl_rotate_bytes != 0 &&
          jsonl_file_.size() + json_text_.size() > options_.jsonl_rotate_bytes) {
        jsonl_file_.close();
        if (::rename(jsonl_path_.c_str(), jsonl_rotated_path_.c_str()) != 0) {
          throw std::system_error(errno, std::generic_category(),
                                  "cannot rename to '" + jsonl_rotated_path_ + "'");
        }
        jsonl_file_.open(jsonl_path_, OutputFile::Mode::kAppend);
      }
      const std::uint64_t before = jsonl_file_.size();
      try {
        jsonl_file_.write(json_text_);
      } catch (...) {
        // A line cut short (a full disk) would glue itself to the next one: take it back.
        jsonl_file_.truncate(before);
        jsonl_file_.close();  // reopen next time (the file may have been removed)
        throw;
      }
    }
  } catch (const std::exception& error) {
    write_failed(error, 0);
  }
  (void) final;
}

void Writer::stall_while_test_file_exists() const {
  if (::access(options_.test_stall_file.c_str(), F_OK) != 0) return;
  spdlog::warn("test hook: writer stalled while {} exists", options_.test_stall_file);
  const timespec pause{0, 20'000'000};
  while (::access(options_.test_stall_file.c_str(), F_OK) == 0)
    ::nanosleep(&pause, nullptr);
  spdlog::warn("test hook: writer resumed");
}

void Writer::run(std::atomic<std::uint64_t>& heartbeat,
                 const std::atomic<std::uint32_t>& rotate_generation,
                 ringbuf::SpscQueue<StatusLine>& status_out) {
  std::int64_t next_tick = monotonic_ns() + kSecondNs;
  std::uint32_t seen_generation = rotate_generation.load(std::memory_order_relaxed);
  const std::int64_t warm_ns = monotonic_ns() + kWarmUpNs;
  bool hot = false;
  bool ended = false;
  while (!ended) {
    ReceiveCounters::add(heartbeat, 1);
    if (!hot && monotonic_ns() >= warm_ns) {
      alloc::mark_this_thread_hot(alloc::HotThread::kWriter);
      hot = true;
    }
    if (WriterMessage* message = from_decoder_.front()) {
      switch (message->kind) {
        case WriterMessage::Kind::kFrame:
          write_frame(*message->arena);
          arenas_back_.try_push(message->arena);  // room for every arena: cannot fail
          arenas_back_.notify();                  // a replaying decoder may be waiting for it
          break;
        case WriterMessage::Kind::kRaw:
          if (options_.pcap) write_raw(*message->raw);
          message->raw->size = 0;
          raw_back_.try_push(message->raw);
          raw_back_.notify();
          break;
        case WriterMessage::Kind::kSnapshot:
          decode_ = message->snapshot;
          break;
        case WriterMessage::Kind::kEnd:
          decode_ = message->snapshot;
          ended = true;
          break;
      }
      from_decoder_.pop();
    } else {
      const std::int64_t wait =
          std::clamp<std::int64_t>(next_tick - monotonic_ns(), 0, 100'000'000);
      from_decoder_.wait_for_data(std::chrono::nanoseconds(wait));
      ++wakeups_;
    }
    const std::uint32_t generation = rotate_generation.load(std::memory_order_relaxed);
    if (generation != seen_generation) {
      seen_generation = generation;
      rotate_outputs();
    }
    const std::int64_t now = monotonic_ns();
    // Packets stopped or started again since the last health: say so now, not at the next tick.
    const bool silence_changed = silent(now) != reported_silent_;
    if (now >= next_tick || silence_changed) {
      if (!options_.test_stall_file.empty()) stall_while_test_file_exists();
      write_health(false);
      StatusLine status;
      const HealthCounters& c = health_.counters;
      fmt::format_to_n(status.text, sizeof status.text - 1,
                       "{}: {} packets, {} frames written, {:.0f} RPM, {} dropped{}{}",
                       to_string(health_.gauges.state), c.datagrams_received, c.frames_written,
                       health_.gauges.rpm_tail,
                       c.kernel_drops + c.ring_overruns + c.frames_dropped_no_arena,
                       health_.gauges.reason.empty() ? "" : " - ", health_.gauges.reason);
      status_out.try_push(status);
      next_tick = silence_changed ? now + kSecondNs : std::max(next_tick + kSecondNs, now);
    }
  }
  alloc::mark_this_thread_cold();
  close_pcap();
  write_health(true);
}

}  // namespace pandarcap
