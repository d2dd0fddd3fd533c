// The writer thread: the only thread that touches the disk.
//
// It takes finished frame arenas, raw-packet batches and the decoder's counter snapshots from the
// decode worker's queue, and
//   - writes each frame as a PCD v0.7 binary file in DIR/frames/ (temporary name, then renamed;
//     partial frames carry "_partial" in the name), keeping at most frames_max_files /
//     frames_max_bytes of frames, those of earlier runs included;
//   - appends raw packets to a classic pcap in DIR/raw/ (".part" while open, renamed when closed),
//     rotated by size and age and on SIGHUP, with the same retention, and the calibration CSV in
//     use saved beside it as DIR/raw/calibration.csv (an earlier run's that differs is kept as
//     calibration_before_<N>.csv);
// Nothing is ever replaced. File numbers continue across runs (frame_<N>_..., pandarcap_..._<N>:
// the next free number is found at start-up), so a restart within the same second or a sensor
// clock that restarts cannot repeat a name; and a finished file is put in place with a rename
// that refuses an existing name (a "_dupN" name is taken instead, counted as
// output_name_collisions). Retention counts every file of ours found at start-up, so restarts
// and crash loops cannot fill the disk.
//   - every second writes DIR/health/pandarcap.prom (temporary file + rename) and appends one line
//     to DIR/health/health.jsonl (rotated to health.jsonl.1 past jsonl_rotate_bytes); and at once,
//     outside that schedule, when packets stop for longer than the no-data timeout or start
//     again (checked at every wake-up, at least every 100 ms), the schedule restarting from there.
// Arenas and batches go back to the decoder as soon as they are written. A write error is
// counted (write_errors, bytes_not_written), logged at most every 10 s, and makes the state
// "degraded" with the error as the reason; the thread carries on with the next file. A pcap whose
// write failed is cut back to its last whole record and closed (a full disk never leaves a
// recording that readers choke on), a frame's temporary file is removed, a health line cut short
// is taken back. A slow disk holds arenas longer, so the
// decoder runs out and drops frames (counted) — the receive thread never waits for the disk.
#pragma once

#include <atomic>
#include <cstdint>
#include <deque>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/health.hpp"
#include "daemon/decode_worker.hpp"
#include "daemon/io/file_output.hpp"
#include "daemon/pcap/capture_reader.hpp"
#include "daemon/pcap/pcap_writer.hpp"
#include "daemon/pipeline_types.hpp"

namespace pandarcap {

struct WriterOptions {
  std::filesystem::path output_dir;       // frames/ and raw/ go under it
  std::filesystem::path health_dir;       // health.jsonl
  std::filesystem::path prometheus_file;  // the .prom textfile
  bool frames = true;
  std::uint64_t frames_max_files = 0;
  std::uint64_t frames_max_bytes = 0;
  bool pcap = true;
  std::uint64_t pcap_rotate_bytes = 0;
  std::uint32_t pcap_rotate_seconds = 0;
  std::uint64_t pcap_max_files = 0;
  std::uint64_t pcap_max_bytes = 0;
  bool prometheus = true;
  bool jsonl = true;
  std::uint64_t jsonl_rotate_bytes = 0;
  std::string sensor_name;
  std::string version;
  std::string decoder;  // decoder target in use, reported in the health output
  double no_data_timeout_seconds = 1.0;
  std::string expected_return_mode = "any";
  int expected_rpm = 600;
  Endpoint pcap_destination;  // the synthesised destination of recorded packets
  std::string calibration_csv;
  // Test hook (PANDARCAP_TEST_STALL_WRITER_FILE): while this file exists, the writer stops at its
  // next once-a-second tick, without a heartbeat, as a writer stuck on a dead disk would. Lets
  // the tests see the watchdog stop and frames drop (counted) behind a stalled writer. "" = off.
  std::string test_stall_file;
};

// One line for sd_notify STATUS=, handed to the main thread once a second.
struct StatusLine {
  char text[200] = {};
};

class Writer {
 public:
  Writer(const WriterOptions& options, DecodeWorker::WriterQueue& from_decoder,
         DecodeWorker::ArenaQueue& arenas_back, DecodeWorker::RawQueue& raw_back,
         const ReceiveCounters& receive, const LiveClock& live);
  ~Writer();

  // Creates the output directories and proves they are writable (writes calibration.csv and a
  // first health file). Throws std::system_error; called before READY=1.
  void prepare();

  // Runs until the decoder's kEnd; then closes the pcap, writes the final health and returns.
  // `rotate_generation` changes on SIGHUP.
  void run(std::atomic<std::uint64_t>& heartbeat,
           const std::atomic<std::uint32_t>& rotate_generation,
           ringbuf::SpscQueue<StatusLine>& status_out);

  // Valid after run() returns.
  const HealthSnapshot& final_health() const noexcept { return health_; }

 private:
  void write_frame(FrameArena& arena);
  void write_raw(RawBatch& batch);
  void open_pcap(std::int64_t first_packet_ns);
  void close_pcap();
  // After a failed write: cut the file back to whole records, count what was lost, close it.
  void abandon_pcap(const std::exception& error, std::uint64_t failed_bytes);
  void finish_pcap_file();  // rename .part (or remove it if it holds no record)
  void finish_leftovers();  // at start: what an interrupted run left (see prepare())
  // At start: the frames and recordings of earlier runs, numbered and sized, into the retention
  // lists (oldest first, then retention applied), and the next free file numbers.
  void adopt_earlier_files();
  // Renames a finished file from `from` to `to` without replacing anything (see file_output);
  // on a collision `to` becomes the name used, counted and logged.
  void put_in_place(const std::string& from, std::string& to);
  void log_fragments(std::int64_t now_monotonic_ns);
  void save_calibration();  // raw/calibration.csv, keeping an earlier one that differs
  void rotate_outputs();
  void write_health(bool final);
  void stall_while_test_file_exists() const;
  void build_health(std::int64_t now_monotonic_ns);  // into health_
  // Seconds since the decoder's last packet (-1: none yet), and whether that is silence.
  double seconds_since_last_packet(std::int64_t now_monotonic_ns) const noexcept;
  bool silent(std::int64_t now_monotonic_ns) const noexcept;
  void write_failed(const std::exception& error, std::uint64_t bytes);
  void enforce_retention(std::deque<std::pair<std::filesystem::path, std::uint64_t>>& files,
                         std::uint64_t max_files, std::uint64_t max_bytes);

  WriterOptions options_;
  DecodeWorker::WriterQueue& from_decoder_;
  DecodeWorker::ArenaQueue& arenas_back_;
  DecodeWorker::RawQueue& raw_back_;
  const ReceiveCounters& receive_;
  const LiveClock& live_;
  bool reported_silent_ = true;  // the last health written said "no data"
  std::filesystem::path frames_dir_, raw_dir_;

  std::vector<std::uint8_t> pcd_buffer_;  // allocated once: frames are encoded in chunks
  std::vector<char> pcap_buffer_;         // the pcap's stdio buffer, allocated once
  std::unique_ptr<PcapWriter> pcap_;
  std::string pcap_final_path_;
  std::int64_t pcap_opened_monotonic_ns_ = 0;
  std::uint64_t pcap_index_ = 0;         // the next recording's number (continues across runs)
  std::uint64_t frame_number_base_ = 0;  // + the frame's sequence = its file number
  std::uint64_t name_collisions_ = 0;
  std::uint64_t wakeups_ = 0;
  LatencyHistogram frame_latency_;
  HealthCounters counters_a_second_ago_{};  // for the per-second wake-up rates
  std::uint64_t fragments_logged_ = 0;
  std::int64_t last_fragment_log_ns_ = -1;
  std::deque<std::pair<std::filesystem::path, std::uint64_t>> frame_files_, pcap_files_;

  DecodeSnapshot decode_;       // the latest counters from the decoder
  DecodeSnapshot decode_prev_;  // the ones a second earlier, for rates
  std::int64_t start_monotonic_ns_ = 0;
  std::int64_t last_tick_ns_ = 0;
  std::uint64_t frames_written_ = 0, frames_written_prev_ = 0;
  std::uint64_t pcd_bytes_ = 0, pcap_packets_ = 0, pcap_packets_not_written_ = 0;
  std::uint64_t pcap_bytes_closed_ = 0;  // in finished files; the open one adds its own
  std::uint64_t write_errors_ = 0, bytes_not_written_ = 0;
  std::int64_t last_error_log_ns_ = -1;
  std::string last_error_;
  HealthCounters previous_counters_{};
  HealthSnapshot health_;

  // Buffers and files reused every second and every frame, so that once warm the writer loop
  // allocates nothing (file names and rendered text are built in place; see README "Latency and
  // allocations").
  std::string prom_path_, prom_temporary_path_, jsonl_path_, jsonl_rotated_path_;
  std::string prom_text_, json_text_;
  OutputFile health_file_, jsonl_file_;
  std::string frame_path_, frame_temporary_path_, pcd_header_;
  OutputFile frame_file_;
};

}  // namespace pandarcap
