// The writer's health record: built from every thread's counters once a second, and published as
// the Prometheus textfile and a line of health.jsonl.
//
//   - build(): the HealthSnapshot from the receive thread's atomics, the decoder's latest
//     snapshot and the writer's own parts (frames, recordings, failed writes), with the per-second
//     rates and the state and reason decided by core/health/health_policy.hpp against the previous
//     record. Filled in place: once warm its strings keep their capacity.
//     The `storage` gauges: each output's bytes written per second over the last minute
//     (a preallocated window of per-second samples, core/health/storage_rate.hpp) and the hours of
//     disk left at that pace, which health.min_hours_left checks.
//   - write(): DIR/pandarcap.prom replaced whole (temporary file + rename: node_exporter never
//     reads half a file; the rename is the finisher thread's, after the data is synced:
//     daemon/output/file_finisher.hpp), one line appended to health.jsonl (kept open; rotated to
//     health.jsonl.1 past jsonl_rotate_bytes; a line cut short by a failed write is taken back so
//     it cannot glue itself to the next; synced every output.sync_interval_seconds, sync_jsonl()).
//     A failure is counted (OutputAccounting), not thrown. Neither may freeze
//     (docs/reliability.md): a write that fails for want of space takes a piece of the health
//     reserve (HealthRoom) and is tried again; a health directory removed while running is made
//     again; health.jsonl is reopened when it is no longer at its path.
//   - The fallback: any other failure of the health files (a disk gone read-only: EROFS; failing:
//     EIO, at the write or at the finisher's sync) sends them to health.fallback_directory
//     (normally the unit's RuntimeDirectory, a tmpfs) until their own directory takes a probe
//     file again. The record then says so (gauges.health_fallback; degraded, "health written to
//     DIR (why)"), re-decided the moment the failure is seen, so the first record there is
//     already true; the journal says so at once and every 10 s. Back home, the fallback's .prom
//     is removed (a monitor must not read a frozen copy) and its health.jsonl kept.
//
// Once warm nothing here allocates (names and rendered text are built in place; see
// docs/performance.md, "Zero allocations"). Owned by the writer thread.
#pragma once

#include <array>
#include <cstdint>
#include <string>

#include "core/health/health.hpp"
#include "core/health/health_policy.hpp"
#include "core/health/storage_rate.hpp"
#include "daemon/io/file_output.hpp"
#include "daemon/live/live_handover.hpp"
#include "daemon/output/file_finisher.hpp"
#include "daemon/output/frame_output.hpp"
#include "daemon/output/health_room.hpp"
#include "daemon/output/mcap_recorder.hpp"
#include "daemon/output/output_accounting.hpp"
#include "daemon/output/pcap_recorder.hpp"
#include "daemon/output/writer_options.hpp"
#include "daemon/pipeline_types.hpp"
#include "daemon/ptc/sensor_status_channel.hpp"

namespace pandarcap {

// What one health record is built from, gathered by the writer thread at the moment of building.
struct HealthSources {
  const ReceiveCounters& receive;
  const DecodeSnapshot& decode;  // the decoder's latest
  const FrameOutput& frames;
  const PcapRecorder& pcap;
  const McapRecorder& mcap;
  const OutputAccounting& accounting;
  std::uint64_t decode_wakeups;  // DecodeLive's, read at this tick
  std::uint64_t writer_wakeups;
  double seconds_since_last_packet;         // -1: none yet
  Silence silence;                          // no packet for the timeout; the receiver's lag
  const SensorStatusSample* sensor_status;  // the sensor's latest status over PTC; null: none
  std::uint64_t ptc_requests;
  std::uint64_t ptc_errors;
  std::uint64_t sensor_status_implausible;
  // The free space of each output's file system (core/health/storage_rate.hpp), asked by the
  // free-space floor this second, and what the floor removed (daemon/output/space_floor.hpp).
  const StorageInputs& storage;
  std::uint64_t files_removed_for_space;
  std::uint64_t bytes_removed_for_space;
  // The live view's counters (daemon/live/live_handover.hpp); null while it is off.
  const live::LiveCounters* live = nullptr;
};

class HealthPublisher {
 public:
  // `options` must outlive the publisher.
  HealthPublisher(const WriterOptions& options, OutputAccounting& accounting, HealthRoom& space,
                  FileFinisher& finisher);

  // At start-up: the file names, the clock the uptime and rates count from, and the buffers.
  void prepare(std::int64_t start_monotonic_ns);
  // The .prom's temporary names (two: one can be with the finisher while the next is written).
  const std::array<std::string, 2>& prometheus_temporary_paths() const noexcept {
    return prom_temporary_paths_;
  }
  const std::string& jsonl_path() const noexcept { return jsonl_path_; }

  // The record as of `now_monotonic_ns`, into snapshot().
  void build(const HealthSources& sources, std::int64_t now_monotonic_ns);
  // After a record is published (write()): it becomes the base of the next one's "what grew" and
  // rates.
  void remember(const DecodeSnapshot& decode, std::int64_t now_monotonic_ns);

  // The first record, before READY=1: proves the health outputs are writable (and puts it on the
  // disk durably). Throws std::system_error.
  void write_first();
  // Every later record, to the health directory or while that fails to the fallback; a failure
  // is counted, never thrown.
  void write(std::int64_t now_monotonic_ns);
  // health.jsonl's data synced, off this thread (output.sync_interval_seconds).
  void sync_jsonl();
  // The finisher's word on a .prom or a sync of health.jsonl.
  void finished(const FinishJob& job);
  const std::string& probe_path() const noexcept { return probe_path_; }

  const HealthSnapshot& snapshot() const noexcept { return health_; }
  // snapshot() as one JSON line, rendered once per record whoever asks first (health.jsonl,
  // the MCAP health message).
  const std::string& json_line();
  // The MCAP counters of snapshot() brought up to date, nothing else: after the last MCAP file
  // is closed with the final record in it, for the exit summary.
  void count_mcap(const McapRecorder& mcap) noexcept;
  // Bytes of health.jsonl lines written (the health output's share of the write rate).
  std::uint64_t jsonl_bytes_written() const noexcept { return jsonl_bytes_written_; }

 private:
  SensorModelId model_ = SensorModelId::kPandar40P;  // the decode worker's, at the last build
  // The health directory: true when both files were written (the .prom handed to the finisher).
  bool write_home(std::int64_t now);
  void write_prometheus(std::int64_t now);  // throws
  // The record's line appended to `file` (opened at `path` if need be; rotated to `rotated`).
  // Throws.
  void append_jsonl(OutputFile& file, const std::string& path, const std::string& rotated);
  // Whether the health directory (and the .prom's) takes a new file again, now.
  bool probe_home();
  // The state and reason decided again from the counters as they are now (a write just failed,
  // the fallback was entered or left): the record written next is true already.
  void reclassify();
  void enter_fallback(std::int64_t now);
  void write_fallback(std::int64_t now);
  // The files' names in health_fallback_dirs[index] (past the end: none left).
  void use_fallback(std::size_t index);
  // Both files written to the fallback in use; false (fallback_error_ says why) when it refuses.
  bool write_fallback_files() noexcept;
  void leave_fallback();

  const WriterOptions& options_;
  OutputAccounting& accounting_;
  HealthRoom& space_;
  FileFinisher& finisher_;
  HealthSnapshot health_;
  Silence silence_{true};  // the last build()'s, for reclassify()
  std::int64_t start_monotonic_ns_ = 0;
  std::int64_t last_tick_ns_ = 0;
  HealthCounters counters_a_second_ago_{};  // for the per-second wake-up rates
  HealthCounters previous_counters_{};      // the last record's: what grew since
  DecodeSnapshot decode_prev_;              // the decoder's counters of the last record, for rates
  WriteRateWindow write_rates_;             // the outputs' bytes, a sample a second
  std::uint64_t jsonl_bytes_written_ = 0;
  // Datagrams the decoder had no raw batch for (the writer behind), at the last build(), when
  // the MCAP files hold the packets: they are missing from those as from the pcap.
  std::uint64_t mcap_packets_not_recorded_ = 0;
  std::string prom_path_, jsonl_path_, jsonl_rotated_path_;
  std::array<std::string, 2> prom_temporary_paths_;
  std::string prom_text_, json_text_;
  bool json_text_current_ = false;  // json_text_ is health_ as it is now
  OutputFile prom_file_, jsonl_file_;
  // Which temporary names are with the finisher, since when (monotonic): the records of two ticks
  // in a row (packets stop) can both be on their way.
  std::array<bool, 2> prom_pending_{};
  std::array<std::int64_t, 2> prom_submitted_ns_{};
  bool jsonl_directory_synced_ = false;  // since health.jsonl was last opened
  // Why the health directory failed (this thread's write, or the finisher's sync); "" = fine.
  std::string home_error_;
  std::string probe_path_, prom_probe_path_;
  std::string fallback_prom_path_, fallback_prom_temporary_path_, fallback_jsonl_path_,
      fallback_jsonl_rotated_path_;
  OutputFile probe_file_, fallback_prom_file_, fallback_jsonl_file_;
  std::int64_t fallback_logged_ns_ = -1;
  std::size_t fallback_index_ = 0;  // in options_.health_fallback_dirs
  std::string fallback_error_;      // why the last fallback refused
};

}  // namespace pandarcap
