// The writer thread: the only thread that touches the disk.
//
// It takes finished frame arenas, raw-packet batches and the decoder's counter snapshots from the
// decode worker's queue and hands each to the part that writes it:
//   - frames as PCD files in DIR/frames/ (daemon/output/frame_output.hpp);
//   - raw packets as pcap recordings in DIR/raw/, with the calibration in use beside them
//     (daemon/output/pcap_recorder.hpp);
//   - with output.mcap, frames, health and (output.mcap_packets) raw packets as MCAP files in
//     DIR/mcap/ (daemon/output/mcap_recorder.hpp);
//   - every second the health record, as DIR/health/pandarcap.prom and a line of
//     DIR/health/health.jsonl (daemon/output/health_publisher.hpp); and at once, outside that
//     schedule, when packets stop for longer than the no-data timeout or start again (checked at
//     every wake-up, at least every 100 ms), the schedule restarting from there.
// Before each health record the free-space floor is held (daemon/output/space_floor.hpp: a
// statvfs per output file system; below output.min_free_bytes / min_free_percent, or the health
// files' room plus 2 s of writing, the oldest of our files are removed; a write that would be
// refused for space asks it first), and its free space feeds the health record's storage gauges,
// with the upload backlog (daemon/output/upload_backlog.hpp: a few milliseconds of directory
// reading a second).
// At start-up (prepare()) it deals with what an interrupted run left
// (daemon/output/output_leftovers.hpp) and adopts earlier runs' files: numbers continue across runs
// and retention counts them, so restarts and crash loops can neither repeat a name nor fill the
// disk. Nothing is ever replaced.
//
// Durable before visible: every file the writer finishes is synced and renamed into place by the
// finisher thread (daemon/output/file_finisher.hpp), which hands back its result at the writer's
// next wake-up; the recordings being written and health.jsonl are synced by it every
// output.sync_interval_seconds. The writer never waits for a sync, only for a free finisher job
// when the disk is slower than the outputs (as it waits for a slow write).
// Arenas and batches go back to the decoder as soon as they are written. A write error is
// counted (write_errors, bytes_not_written; daemon/output/output_accounting.hpp), logged at most
// every 10 s, and makes the state "degraded" with the error as the reason; the thread carries on
// with the next file. A slow disk holds arenas longer, so the decoder runs out and drops frames
// (counted) — the receive thread never waits for the disk. Once warm, the loop allocates nothing.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>

#include "core/health/health.hpp"
#include "daemon/live/live_handover.hpp"
#include "daemon/output/file_finisher.hpp"
#include "daemon/output/frame_output.hpp"
#include "daemon/output/health_publisher.hpp"
#include "daemon/output/health_room.hpp"
#include "daemon/output/mcap_recorder.hpp"
#include "daemon/output/output_accounting.hpp"
#include "daemon/output/pcap_recorder.hpp"
#include "daemon/output/space_floor.hpp"
#include "daemon/output/upload_backlog.hpp"
#include "daemon/output/writer_options.hpp"
#include "daemon/pipeline_types.hpp"
#include "daemon/ptc/sensor_status_channel.hpp"

namespace pandarcap {

// One line for sd_notify STATUS=, handed to the main thread once a second.
struct StatusLine {
  char text[200] = {};  // sd_notify's STATUS=
  // For the journal's state changes (core/health/health_state_log.hpp), logged by the main thread.
  HealthState state = HealthState::kNoData;
  char reason[400] = {};  // cut to fit
};

class Writer final : private FinishReceiver {
 public:
  Writer(const WriterOptions& options, WriterQueue& from_decoder, ArenaQueue& arenas_back,
         RawQueue& raw_back, const ReceiveCounters& receive, const DecodeLive& live,
         SensorStatusChannel& sensor_status);
  ~Writer();

  // Creates the output directories and proves they are writable (writes calibration.csv and a
  // first health file). Throws std::system_error; called before READY=1.
  void prepare();

  // Runs until the decoder's kEnd; then closes the pcap, writes the final health and returns.
  // `rotate_generation` changes on SIGHUP.
  void run(std::atomic<std::uint64_t>& heartbeat,
           const std::atomic<std::uint32_t>& rotate_generation,
           ringbuf::SpscQueue<StatusLine>& status_out);

  // The live view ([live] foxglove): every frame and health record is offered to it too
  // (daemon/live/live_publish.hpp). Before run(); `live` outlives it.
  void attach_live(live::LiveHandover& live) noexcept { live_view_ = &live; }

  // Valid after run() returns.
  const HealthSnapshot& final_health() const noexcept { return health_.snapshot(); }

 private:
  // The health record at `now` (the moment the loop decided on it): built from everything's
  // counters, published.
  void write_health(std::int64_t now_monotonic_ns);
  HealthSources sources(std::int64_t now_monotonic_ns) const noexcept;
  // The floor held and the free space asked, and the upload backlog read on (once a second, and
  // at start-up).
  void tend_floor(std::int64_t now_monotonic_ns) noexcept;
  // At start-up: the upload directories, and the recorders' retention heard.
  void watch_uploads();
  void take_sensor_status() noexcept;  // the poller's latest answer, if any came
  void log_fragments(std::int64_t now_monotonic_ns);
  // A finished job back from the finisher, to the part whose file it was.
  void finished(const FinishJob& job) override;
  // Whether it stalled: the loop then decides again, at a later moment.
  bool stall_while_test_file_exists() const;
  // `now`, or the moment the receiver saw a stop if that was earlier: it listened no longer.
  std::int64_t listened_until(std::int64_t now_monotonic_ns) const noexcept;
  // Seconds since the decoder's last packet (-1: none yet), until the listening ended, and
  // whether that is silence.
  double seconds_since_last_packet(std::int64_t now_monotonic_ns) const noexcept;
  bool silent(std::int64_t now_monotonic_ns) const noexcept;
  // Whether silent, and then how far the moment up to which the receiver has seen everything
  // lies behind the listening, when further than its looks can explain (0: they are current).
  // The hold and the record each read it at the one moment the loop decided on.
  Silence silence_at(std::int64_t now_monotonic_ns) const noexcept;
  // At each turn of the loop: whether the health waits because it would say no_data and the
  // receiver's looks are not current (a pause of the process, a backlog).
  bool silence_unconfirmed(std::int64_t now_monotonic_ns) noexcept;

  WriterOptions options_;
  // options_.calibration_csv follows the decoder's model (a live "auto").
  void follow_model();
  WriterQueue& from_decoder_;
  ArenaQueue& arenas_back_;
  RawQueue& raw_back_;
  const ReceiveCounters& receive_;
  const DecodeLive& live_;
  // The parts, which count their failures in accounting_ and read options_ (declared first).
  OutputAccounting accounting_;
  HealthRoom space_;       // the health files' room, whatever fills their disk
  FileFinisher finisher_;  // the syncs and renames, on their own thread
  FrameOutput frames_;
  PcapRecorder pcap_;
  McapRecorder mcap_;
  HealthPublisher health_;
  SpaceFloor floor_;  // output.min_free_bytes, and the free space health reports
  std::array<int, kStorageOutputCount> floor_handles_{-1, -1, -1, -1};  // per storage output
  StorageInputs storage_;  // the free space of each output's file system, this second
  UploadBacklog upload_;   // how far the upload is behind (output.upload)

  DecodeSnapshot decode_;  // the latest counters from the decoder
  SensorStatusChannel& sensor_status_;
  std::optional<SensorStatusSample> latest_sensor_status_;
  bool reported_silent_ = true;            // the last health written said "no data"
  std::int64_t unconfirmed_since_ns_ = 0;  // since when silence_unconfirmed says so (0: not)
  bool holding_ = false;                   // the health waits for the receiver's looks
  std::uint64_t wakeups_ = 0;
  std::int64_t next_sync_ns_ = 0;  // the recordings' and health.jsonl's next sync
  std::uint64_t fragments_logged_ = 0;
  std::int64_t last_fragment_log_ns_ = -1;
  live::LiveHandover* live_view_ = nullptr;
};

}  // namespace pandarcap
