#include "daemon/output/writer.hpp"

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>

#include "core/units.hpp"
#include "daemon/allocation_counter.hpp"
#include "daemon/clocks.hpp"
#include "daemon/io/file_output.hpp"
#include "daemon/live/live_publish.hpp"
#include "daemon/output/output_directories.hpp"
#include "daemon/output/output_leftovers.hpp"

namespace pandarcap {
namespace {

// How long a record that would say no_data waits for the receiver's looks to be current
// (Writer::silence_unconfirmed): working through a full queue of the default size after a pause
// takes well under this, and the record is at most this much later than its second. And how
// late a look may be (past the receiver's own interval) on a busy machine and still count.
constexpr std::int64_t kSilenceHoldNs = 1'000'000'000;
constexpr std::int64_t kLookSlackNs = 150'000'000;

// Proves `dir` takes a new file (permissions, a read-only mount, a full inode table) by creating
// and removing one: READY=1 promises writable outputs. Throws std::system_error.
void probe_writable(const std::filesystem::path& dir) {
  const std::filesystem::path probe = dir / kProbeFileName;
  OutputFile file(probe, OutputFile::Mode::kCreate);
  file.close();
  ::unlink(probe.c_str());
}

}  // namespace

Writer::Writer(const WriterOptions& options, WriterQueue& from_decoder, ArenaQueue& arenas_back,
               RawQueue& raw_back, const ReceiveCounters& receive, const DecodeLive& live,
               SensorStatusChannel& sensor_status)
    : options_(options),
      from_decoder_(from_decoder),
      arenas_back_(arenas_back),
      raw_back_(raw_back),
      receive_(receive),
      live_(live),
      space_(options_.prometheus || options_.jsonl ? options_.health_dir : std::filesystem::path()),
      finisher_(*this),
      frames_(options_, accounting_, space_, finisher_),
      pcap_(options_, accounting_, space_, finisher_),
      mcap_(options_, accounting_, space_, finisher_),
      health_(options_, accounting_, space_, finisher_),
      // A floor asked for is held at least where it can act (space_floor.hpp); none asked for,
      // none held: nothing of ours is removed but by retention.
      floor_(options_.min_free_bytes, options_.min_free_percent,
             options_.min_free_bytes != 0 || options_.min_free_percent > 0 ? kOutputFloorBytes : 0),
      upload_(options_.upload),
      sensor_status_(sensor_status) {}

Writer::~Writer() = default;

void Writer::follow_model() {
  // A live "auto" whose packets named another model than the table it started with: that
  // model's table is the one its decoder uses, and the one the recordings must carry (their
  // sidecars, raw/calibration.csv). Once, when the decoder switches.
  const auto at = static_cast<std::size_t>(decode_.model);
  if (decode_.model == options_.calibration_model || options_.calibration_by_model[at].empty())
    return;
  options_.calibration_model = decode_.model;
  options_.calibration_csv = options_.calibration_by_model[at];
  if (options_.pcap) pcap_.save_calibration(options_.calibration_csv);
}

void Writer::prepare() {
  const std::int64_t start = monotonic_ns();
  decode_.monotonic_ns = start;
  health_.prepare(start);
  std::filesystem::create_directories(options_.health_dir);
  if (options_.prometheus && options_.prometheus_file.has_parent_path()) {
    std::filesystem::create_directories(options_.prometheus_file.parent_path());
  }
  if (options_.frames) {
    std::filesystem::create_directories(frames_.directory());
    probe_writable(frames_.directory());
  }
  if (options_.pcap) std::filesystem::create_directories(pcap_.directory());
  if (options_.mcap) std::filesystem::create_directories(mcap_.directory());
  OutputLeftovers leftovers;
  if (options_.frames) leftovers.frames_dir = frames_.directory();
  if (options_.pcap) leftovers.raw_dir = pcap_.directory();
  if (options_.mcap) leftovers.mcap_dir = mcap_.directory();
  if (options_.prometheus)
    leftovers.prometheus_temporary_paths.assign(health_.prometheus_temporary_paths().begin(),
                                                health_.prometheus_temporary_paths().end());
  if (options_.jsonl) leftovers.jsonl_path = health_.jsonl_path();
  leftovers.health_probe_path = health_.probe_path();
  finish_leftovers(leftovers, accounting_);
  watch_uploads();
  if (options_.frames) frames_.adopt_earlier_files();
  if (options_.pcap) {
    pcap_.adopt_earlier_files();
    pcap_.save_calibration(options_.calibration_csv);
    if (!options_.sensor_json.empty()) pcap_.save_sensor_info(options_.sensor_json);
  }
  if (options_.mcap) {
    mcap_.adopt_earlier_files();
    mcap_.prepare();
  }
  frames_.reserve();
  // The floor watches the outputs' directories (the health directory for its free space only),
  // and is held once already: earlier runs' files may have brought the disk under it.
  if (options_.frames) floor_handles_[0] = floor_.watch(frames_.directory(), FloorKind::kFrames);
  if (options_.pcap) floor_handles_[1] = floor_.watch(pcap_.directory(), FloorKind::kRecordings);
  if (options_.mcap) floor_handles_[2] = floor_.watch(mcap_.directory(), FloorKind::kMcap);
  if (options_.jsonl) floor_handles_[3] = floor_.watch(options_.health_dir, FloorKind::kNone);
  floor_.on_removed([this](FloorKind kind, std::string_view path, std::uint64_t bytes) {
    if (kind == FloorKind::kFrames) frames_.removed_for_space(path);
    if (kind == FloorKind::kRecordings) pcap_.removed_for_space(path);
    if (kind == FloorKind::kMcap) mcap_.removed_for_space(path);
    upload_.removed(path, bytes, UploadBacklog::Remover::kFloor);
  });
  floor_.prepare();
  // A write the guard would refuse for space asks the floor first.
  space_.make_room_with([this](std::string_view directory, std::uint64_t bytes) {
    return floor_.make_room(directory, bytes, monotonic_ns());
  });
  upload_.prepare();
  tend_floor(start);
  // Room to write, and the health files' room: a disk short of them fails the start (73), as
  // --check-config says it would. Asked only now: what an interrupted run left is finished (a
  // power cut's .part must not wait for space), and a floor asked for has removed the oldest
  // files of ours first, so a disk our own recordings filled starts again.
  std::vector<std::string> space;
  const std::vector<std::string> short_of_space = space_problems(options_, space);
  if (!short_of_space.empty()) throw std::runtime_error(short_of_space.front());
  space_.prepare();
  // Proves the health directories are writable before the daemon reports ready.
  take_sensor_status();
  health_.build(sources(start), start);
  health_.write_first();
}

void Writer::watch_uploads() {
  // raw/ and mcap/ (frames/ with output.upload_frames), watched whether or not upload is on:
  // without it the figures are the recordings kept here.
  if (options_.pcap) upload_.watch(pcap_.directory());
  if (options_.mcap) upload_.watch(mcap_.directory());
  if (options_.frames && options_.upload_frames) upload_.watch(frames_.directory());
  const auto by_retention = [this](std::string_view path, std::uint64_t bytes) {
    upload_.removed(path, bytes, UploadBacklog::Remover::kRetention);
  };
  pcap_.retention().on_removed(by_retention);
  mcap_.retention().on_removed(by_retention);
  frames_.retention().on_removed(by_retention);
}

void Writer::tend_floor(std::int64_t now) noexcept {
  // The floor never below the health files' room plus 2 s of writing at the last record's rate.
  floor_.write_rate(health_.snapshot().gauges.storage.written_bytes_per_second_total, now);
  floor_.tend(now);
  upload_.step();
  upload_.fill(realtime_ns(), storage_.upload);
  storage_.files_removed_before_upload = upload_.files_removed_before_upload();
  storage_.bytes_removed_before_upload = upload_.bytes_removed_before_upload();
  for (std::size_t i = 0; i < kStorageOutputCount; ++i) {
    storage_.free_bytes[i] =
        floor_handles_[i] < 0 ? std::nullopt : floor_.free_bytes(floor_handles_[i]);
    storage_.file_system[i] = floor_handles_[i] < 0 ? -1 : floor_.file_system(floor_handles_[i]);
  }
}

HealthSources Writer::sources(std::int64_t now) const noexcept {
  return HealthSources{
      .receive = receive_,
      .decode = decode_,
      .frames = frames_,
      .pcap = pcap_,
      .mcap = mcap_,
      .accounting = accounting_,
      .decode_wakeups = live_.wakeups.load(std::memory_order_relaxed),
      .writer_wakeups = wakeups_,
      .seconds_since_last_packet = seconds_since_last_packet(now),
      .silence = silence_at(now),
      .sensor_status = latest_sensor_status_ ? &*latest_sensor_status_ : nullptr,
      .ptc_requests = sensor_status_.requests.load(std::memory_order_relaxed),
      .ptc_errors = sensor_status_.errors.load(std::memory_order_relaxed),
      .sensor_status_implausible = sensor_status_.implausible.load(std::memory_order_relaxed),
      .storage = storage_,
      .files_removed_for_space = floor_.files_removed(),
      .bytes_removed_for_space = floor_.bytes_removed(),
      .live = live_view_ != nullptr ? &live_view_->counters : nullptr};
}

void Writer::take_sensor_status() noexcept {
  SensorStatusSample sample;
  while (sensor_status_.samples.try_pop(sample))
    latest_sensor_status_ = sample;
}

void Writer::finished(const FinishJob& job) {
  switch (job.owner) {
    case FinishOwner::kFrames:
      frames_.finished(job);
      break;
    case FinishOwner::kRecordings:
    case FinishOwner::kSidecars:
      pcap_.finished(job);
      break;
    case FinishOwner::kMcap:
      mcap_.finished(job);
      break;
    case FinishOwner::kHealth:
      health_.finished(job);
      break;
  }
}

void Writer::write_health(std::int64_t now) {
  pcap_.flush();  // the recordings on disk are at most a second behind
  if (options_.mcap) mcap_.flush();
  // ... and on the disk at most output.sync_interval_seconds behind (the finisher syncs them).
  if (options_.sync_interval_seconds > 0 && now >= next_sync_ns_) {
    if (options_.pcap) pcap_.sync_open_file();
    if (options_.mcap) mcap_.sync_open_file();
    health_.sync_jsonl();
    next_sync_ns_ = now + static_cast<std::int64_t>(options_.sync_interval_seconds * 1e9);
  }
  finisher_.collect();
  take_sensor_status();
  tend_floor(now);
  health_.build(sources(now), now);
  log_fragments(now);
  reported_silent_ = silent(now);
  space_.tend();
  health_.write(now);
  health_.remember(decode_, now);
  if (options_.mcap) {
    mcap_.write_health(health_.json_line(), realtime_ns());
  }
  if (live_view_ != nullptr) live::offer_health(*live_view_, health_.json_line(), realtime_ns());
}

void Writer::log_fragments(std::int64_t now) {
  const std::uint64_t fragments = health_.snapshot().counters.frames_fragment;
  if (fragments == fragments_logged_) return;
  if (last_fragment_log_ns_ >= 0 && now - last_fragment_log_ns_ < 10 * kNsPerSecond) return;
  spdlog::info(
      "{} frame fragment{} not written (partial frames under output.frames_min_fraction of a "
      "revolution; {} since start)",
      fragments - fragments_logged_, fragments - fragments_logged_ == 1 ? "" : "s", fragments);
  fragments_logged_ = fragments;
  last_fragment_log_ns_ = now;
}

std::int64_t Writer::listened_until(std::int64_t now) const noexcept {
  // A stop ends the listening, not the sensor's sending: the silence is measured up to it.
  const std::int64_t stopped =
      receive_.stopped_listening_monotonic_ns.load(std::memory_order_relaxed);
  return stopped > 0 ? std::min(now, stopped) : now;
}

double Writer::seconds_since_last_packet(std::int64_t now) const noexcept {
  now = listened_until(now);
  // Live, the receiver's note of the newest arrival; a replay's, the decoder's of its taking.
  const std::int64_t last =
      std::max(receive_.last_arrival_monotonic_ns.load(std::memory_order_relaxed),
               live_.last_packet_monotonic_ns.load(std::memory_order_relaxed));
  return last == 0 ? -1.0 : static_cast<double>(std::max<std::int64_t>(now - last, 0)) / 1e9;
}

bool Writer::silent(std::int64_t now) const noexcept {
  const double since = seconds_since_last_packet(now);
  return since < 0 || since > options_.no_data_timeout_seconds;
}

Silence Writer::silence_at(std::int64_t now) const noexcept {
  // seen_until first (acquire): the arrivals a look noted before it are read with it, so a
  // look found current is never paired with an older last packet.
  std::int64_t seen_until = receive_.seen_until_monotonic_ns.load(std::memory_order_acquire);
  const std::int64_t interval = receive_.look_interval_ns.load(std::memory_order_relaxed);
  const bool is_silent = silent(now);
  // Before the receiver's first look that left nothing unseen: since it began to listen. A
  // replay makes no looks, and its silence is the decoder's own.
  if (seen_until == 0)
    seen_until = receive_.listening_since_monotonic_ns.load(std::memory_order_relaxed);
  if (!is_silent || seen_until == 0) return Silence(is_silent);
  const std::int64_t behind = listened_until(now) - seen_until;
  return Silence(true, behind <= interval + kLookSlackNs ? 0.0 : static_cast<double>(behind) / 1e9);
}

bool Writer::silence_unconfirmed(std::int64_t now) noexcept {
  // A silence is the sensor's only while the receiver's looks are current: every packet that
  // arrived until a moment no further back than its own interval between looks has been seen
  // (ReceiveCounters::seen_until_monotonic_ns). Not so after a pause of the process (of any
  // length: the writer's first turn can come before the receiver's first look), nor while it
  // works through a queue that filled (its packets are from before it filled; the kernel
  // dropped the later ones, and their count is noted as an arrival when read). Then the record
  // waits, kSilenceHoldNs at most: past that the receiver itself is behind, and the record goes
  // out saying so (degraded, Silence in core/health/health_policy.hpp), not no_data. A source
  // that makes no looks (a replay) is not waited for.
  if (!(silence_at(now).receiver_behind_seconds > 0)) {
    unconfirmed_since_ns_ = 0;
    holding_ = false;
    return false;
  }
  if (unconfirmed_since_ns_ == 0) unconfirmed_since_ns_ = now;
  holding_ = now - unconfirmed_since_ns_ < kSilenceHoldNs;
  return holding_;
}

bool Writer::stall_while_test_file_exists() const {
  if (::access(options_.test_stall_file.c_str(), F_OK) != 0) return false;
  spdlog::warn("test hook: writer stalled while {} exists", options_.test_stall_file);
  const timespec pause{0, 20'000'000};
  while (::access(options_.test_stall_file.c_str(), F_OK) == 0)
    ::nanosleep(&pause, nullptr);
  spdlog::warn("test hook: writer resumed");
  return true;
}

void Writer::run(std::atomic<std::uint64_t>& heartbeat,
                 const std::atomic<std::uint32_t>& rotate_generation,
                 ringbuf::SpscQueue<StatusLine>& status_out) {
  std::int64_t next_tick = monotonic_ns() + kNsPerSecond;
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
    finisher_.collect();  // files put in place since: counted, listed for retention
    if (WriterMessage* message = from_decoder_.front()) {
      switch (message->kind) {
        case WriterMessage::Kind::kFrame:
          if (options_.frames) frames_.write(*message->arena);
          if (options_.mcap) mcap_.write_frame(*message->arena);
          if (live_view_ != nullptr) {
            live::offer_frame(*live_view_, message->arena->frame, options_.mcap_file.frame_id,
                              message->arena->completed_log_ns > 0
                                  ? message->arena->completed_log_ns
                                  : message->arena->frame.info.start_ns);
          }
          arenas_back_.try_push(message->arena);  // room for every arena: cannot fail
          arenas_back_.notify();                  // a replaying decoder may be waiting for it
          break;
        case WriterMessage::Kind::kRaw:
          if (options_.pcap) pcap_.write(*message->raw);
          if (options_.mcap && options_.mcap_file.packets) mcap_.write_packets(*message->raw);
          message->raw->size = 0;
          raw_back_.try_push(message->raw);
          raw_back_.notify();
          break;
        case WriterMessage::Kind::kSnapshot:
          decode_ = message->snapshot;
          follow_model();
          break;
        case WriterMessage::Kind::kEnd:
          decode_ = message->snapshot;
          follow_model();
          ended = true;
          break;
      }
      from_decoder_.pop();
    } else {
      // The decoder's snapshots wake this loop ten times a second; the cap only bounds how late
      // a silence (no_data_timeout_seconds) is noticed if they stop. A cap of their own period
      // would add a wake-up out of phase with each of them.
      // While a record waits for the receiver's looks (silence_unconfirmed), in short slices.
      const std::int64_t wait = std::clamp<std::int64_t>(next_tick - monotonic_ns(), 0,
                                                         holding_ ? 2'000'000 : 250'000'000);
      from_decoder_.wait_for_data(std::chrono::nanoseconds(wait));
      ++wakeups_;
    }
    const std::uint32_t generation = rotate_generation.load(std::memory_order_relaxed);
    if (generation != seen_generation) {
      seen_generation = generation;
      pcap_.rotate();
      mcap_.rotate();
    }
    const std::int64_t now = monotonic_ns();
    const bool held = silence_unconfirmed(now);
    // Packets stopped or started again since the last health: say so now, not at the next tick.
    const bool silence_changed = silent(now) != reported_silent_;
    if (!held && (now >= next_tick || silence_changed)) {
      // A stalled writer's record is decided again after the stall, as after a slow write.
      if (!options_.test_stall_file.empty() && stall_while_test_file_exists()) continue;
      write_health(now);
      StatusLine status;
      const HealthSnapshot& h = health_.snapshot();
      const HealthCounters& c = h.counters;
      // The health files' whereabouts first when they are not home: a long reason is cut to fit.
      const HealthFallbackGauges& fallback = h.gauges.health_fallback;
      fmt::format_to_n(status.text, sizeof status.text - 1,
                       "{}{}{}: {} packets, {} frames written, {:.0f} RPM, {} dropped{}{}",
                       to_string(h.gauges.state),
                       !fallback.active             ? ""
                       : fallback.directory.empty() ? ", health written nowhere"
                                                    : ", health written to ",
                       fallback.active ? fallback.directory : std::string_view(),
                       c.datagrams_received, c.frames_written, h.gauges.rpm_tail,
                       c.kernel_drops + c.ring_overruns + c.frames_dropped_no_arena,
                       h.gauges.reason.empty() ? "" : " - ", h.gauges.reason);
      status.state = h.gauges.state;
      fmt::format_to_n(status.reason, sizeof status.reason - 1, "{}", h.gauges.reason);
      status_out.try_push(status);
      next_tick = silence_changed ? now + kNsPerSecond : std::max(next_tick + kNsPerSecond, now);
    }
  }
  alloc::mark_this_thread_cold();
  pcap_.close();
  finisher_.drain();  // every file of this run in place (or its failure counted)
  // What the recordings hold on disk now, not what was written to them: files of this run
  // removed while it ran are counted as lost.
  pcap_.verify_on_disk();
  if (options_.mcap) mcap_.drain();  // every message handed over counted in the final record
  // The final record goes into the MCAP file too, before it is closed.
  write_health(monotonic_ns());
  mcap_.close();
  finisher_.drain();  // the last MCAP file and the final .prom synced and in place
  mcap_.verify_on_disk();
  // The exit summary (final_health) counts that last message too; health.jsonl's last line,
  // written before it, cannot.
  health_.count_mcap(mcap_);
  space_.remove();  // a clean end: the health files' room is not needed any more
}

}  // namespace pandarcap
