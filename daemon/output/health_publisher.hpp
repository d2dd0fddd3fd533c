// The writer's health record: built from every thread's counters once a second, and published as
// the Prometheus textfile and a line of health.jsonl.
//
//   - build(): the HealthSnapshot from the receive thread's atomics, the decoder's latest
//     snapshot and the writer's own parts (frames, recordings, failed writes), with the per-second
//     rates and the state and reason decided by core/health_policy.hpp against the previous
//     record. Filled in place: once warm its strings keep their capacity.
//     The `storage` gauges: each output's bytes written per second over the last minute
//     (a preallocated window of per-second samples, core/storage_rate.hpp) and the hours of disk
//     left at that pace, which health.min_hours_left checks.
//   - write(): DIR/pandarcap.prom replaced whole (temporary file + rename: node_exporter never
//     reads half a file), one line appended to health.jsonl (kept open; rotated to
//     health.jsonl.1 past jsonl_rotate_bytes; a line cut short by a failed write is taken back so
//     it cannot glue itself to the next). A failure is counted (OutputAccounting), not thrown.
//     Neither may freeze (docs/reliability.md): a write that fails for want of space takes a
//     piece of the health reserve (SpaceGuard) and is tried again; a health directory removed
//     while running is made again; health.jsonl is reopened when it is no longer at its path.
//
// Once warm nothing here allocates (names and rendered text are built in place; see
// docs/performance.md, "Zero allocations"). Owned by the writer thread.
#pragma once

#include <cstdint>
#include <string>

#include "core/health.hpp"
#include "core/storage_rate.hpp"
#include "daemon/io/file_output.hpp"
#include "daemon/live/live_handover.hpp"
#include "daemon/output/frame_output.hpp"
#include "daemon/output/mcap_recorder.hpp"
#include "daemon/output/output_accounting.hpp"
#include "daemon/output/pcap_recorder.hpp"
#include "daemon/output/space_guard.hpp"
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
  bool silent;                              // no packet yet, or none for the no-data timeout
  const SensorStatusSample* sensor_status;  // the sensor's latest status over PTC; null: none
  std::uint64_t ptc_requests;
  std::uint64_t ptc_errors;
  std::uint64_t sensor_status_implausible;
  // The free space of each output's file system (core/storage_rate.hpp), asked by the free-space
  // floor this second, and what the floor removed (daemon/output/space_floor.hpp).
  const StorageInputs& storage;
  std::uint64_t files_removed_for_space;
  std::uint64_t bytes_removed_for_space;
  // The live view's counters (daemon/live/live_handover.hpp); null while it is off.
  const live::LiveCounters* live = nullptr;
};

class HealthPublisher {
 public:
  // `options` must outlive the publisher.
  HealthPublisher(const WriterOptions& options, OutputAccounting& accounting, SpaceGuard& space);

  // At start-up: the file names, the clock the uptime and rates count from, and the buffers.
  void prepare(std::int64_t start_monotonic_ns);
  const std::string& prometheus_temporary_path() const noexcept { return prom_temporary_path_; }
  const std::string& jsonl_path() const noexcept { return jsonl_path_; }

  // The record as of `now_monotonic_ns`, into snapshot().
  void build(const HealthSources& sources, std::int64_t now_monotonic_ns);
  // After a record is published: it becomes the base of the next one's "what grew" and rates.
  void remember(const DecodeSnapshot& decode, std::int64_t now_monotonic_ns);

  // The first record, before READY=1: proves the health outputs are writable. Throws
  // std::system_error.
  void write_first();
  // Every later record; a failure is counted, never thrown.
  void write();

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
  void write_prometheus();  // throws
  void write_jsonl_line();  // throws

  const WriterOptions& options_;
  OutputAccounting& accounting_;
  SpaceGuard& space_;
  HealthSnapshot health_;
  std::int64_t start_monotonic_ns_ = 0;
  std::int64_t last_tick_ns_ = 0;
  HealthCounters counters_a_second_ago_{};  // for the per-second wake-up rates
  HealthCounters previous_counters_{};      // the last record's: what grew since
  DecodeSnapshot decode_prev_;              // the decoder's counters of the last record, for rates
  WriteRateWindow write_rates_;             // the outputs' bytes, a sample a second
  std::uint64_t jsonl_bytes_written_ = 0;
  std::string prom_path_, prom_temporary_path_, jsonl_path_, jsonl_rotated_path_;
  std::string prom_text_, json_text_;
  bool json_text_current_ = false;  // json_text_ is health_ as it is now
  OutputFile prom_file_, jsonl_file_;
};

}  // namespace pandarcap
