// Raw packets recorded as classic pcap files: DIR/raw/pandarcap_<UTC first packet>_<N>.pcap, or
// with output.pcap_compression = "zstd" the same stream compressed, NAME.pcap.zst (one zstd frame
// per file, a block ended at every flush; daemon/pcap/zstd_write_stream.hpp). Everything below
// holds for both; sizes (rotation, retention, bytes written) are the files' bytes on disk.
//
// A recording is written as NAME.pcap.part and renamed to NAME.pcap when closed (without
// replacing anything: a taken name becomes "_dupN", counted). Durable before visible: the rename
// is the finisher thread's (daemon/output/file_finisher.hpp), after the data is synced; the open
// recording's data is synced every output.sync_interval_seconds (sync_open_file(); its directory
// the first time, so its .part name survives too), so a power cut loses at most that much, and
// the next start finishes the .part. Beside each finished recording go its sidecars,
// NAME.calibration.csv and NAME.sensor.json (the calibration and the sensor facts it was made
// with: a recording uploaded on its own still decodes right), put in place before it. It is closed
// and a new one begun when it reaches pcap_rotate_bytes or pcap_rotate_seconds, on SIGHUP
// (rotate()) and at the end; one that holds no record is removed instead. N continues across runs,
// and retention (pcap_max_files / pcap_max_bytes) counts earlier runs' recordings too.
//
// Failures: a packet pcap cannot hold (a time outside its range) is counted and skipped. A failed
// write (a full disk) cuts the file back to the last flush, which ends on a whole record, and
// closes it (readers never choke on a cut record); the records taken back and the rest of the
// batch are counted as not written, and the next batch tries a new file. Each batch is flushed
// whole, so a crash loses at most the batch being written. A batch is not written while raw/'s
// file system is down to the space kept for the health files (HealthRoom): counted as not
// written.
//
// Recordings that vanish (raw/ removed while running, a remount over it): raw/ is made again at
// the next file. The open recording is checked at every flush; once it is no longer at its path
// its packets are lost (packets_lost(), no longer counted as on disk) and the next batch starts a
// new file. This run's finished recordings are checked again at the end (verify_on_disk), so the
// exit summary's "packets recorded" is what is on disk, less what retention removed on purpose.
//
// The calibration the recordings are decoded with is saved beside them (save_calibration).
// Owned by the writer thread; once warm, recording a batch allocates nothing, a new file
// (rotation, SIGHUP) and a failed write included: one PcapWriter serves file after file, the
// names are made in strings that keep their memory, and failures travel as io::IoError codes.
#pragma once

#include <array>
#include <cstdint>
#include <exception>
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "daemon/output/file_finisher.hpp"
#include "daemon/output/health_room.hpp"
#include "daemon/output/output_accounting.hpp"
#include "daemon/output/retention.hpp"
#include "daemon/output/writer_options.hpp"
#include "daemon/pcap/pcap_writer.hpp"
#include "daemon/pipeline_types.hpp"

namespace pandarcap {

class PcapRecorder {
 public:
  // `options` must outlive the recorder.
  PcapRecorder(const WriterOptions& options, OutputAccounting& accounting, HealthRoom& space,
               FileFinisher& finisher);
  ~PcapRecorder();

  const std::filesystem::path& directory() const noexcept { return dir_; }
  // At start-up, after the leftovers are finished: earlier runs' recordings numbered and listed
  // for retention.
  void adopt_earlier_files();
  // raw/sensor.json := `json`: where the calibration came from, the sensor's identity and
  // configuration (replaced each start: it describes the sensor the recordings now come from).
  void save_sensor_info(std::string_view json);
  // raw/calibration.csv := `csv`. When an earlier run used other angles, its table is kept (never
  // replaced) as calibration_before_<N>.csv: recordings numbered below N were made with it.
  // Throws std::system_error.
  void save_calibration(std::string_view csv);

  // Records the batch's packets, then flushes; failures are counted, never thrown.
  void write(const RawBatch& batch);
  // Pushes what is buffered to the file (the recording on disk at most a second behind).
  void flush();
  // Finishes the open recording (if any); the next packet starts a new one.
  void close();
  // SIGHUP: logged, and the open recording finished.
  void rotate();
  // The open recording's data synced, off this thread (output.sync_interval_seconds).
  void sync_open_file();
  // The finisher's word on a recording or a sidecar.
  void finished(const FinishJob& job);

  // This run's finished recordings that are no longer on disk (removed by someone else): their
  // packets counted as lost. At the end, after close().
  void verify_on_disk();
  // Its retention list: the writer hears of each removal (the upload backlog counts it).
  Retention& retention() noexcept { return retention_; }
  // A finished file of ours removed by the free-space floor (space_floor.hpp): removed on
  // purpose, as retention's are, so not counted as lost.
  void removed_for_space(std::string_view path) noexcept {
    retention_.forget(path);
    recorded_.forget(path);
  }

  // Every packet written to a recording (monotonic, as a Prometheus counter must be): those on
  // disk are packets_written() - packets_lost().
  std::uint64_t packets_written() const noexcept { return packets_written_; }
  std::uint64_t packets_not_written() const noexcept { return packets_not_written_; }
  std::uint64_t packets_lost() const noexcept { return packets_lost_; }
  // In finished recordings and in the open one.
  std::uint64_t bytes_written() const noexcept;

 private:
  io::IoError open(std::int64_t first_packet_ns);
  // The open recording is no longer at its path: its packets are lost, the file let go.
  void lose_open_file();
  // After a failed write: cut the file back to whole records, count what was lost, close it.
  template <class Error>
  void abandon(const Error& error, std::uint64_t failed_bytes);
  void finish_file();  // rename .part (or remove it if it holds no record)
  // The sidecars of the recording about to be put in place as final_path_, written as temporary
  // files and handed to the finisher before it.
  void write_sidecars();

  const WriterOptions& options_;
  OutputAccounting& accounting_;
  HealthRoom& space_;
  FileFinisher& finisher_;
  std::filesystem::path dir_;
  int volume_;  // dir_'s file system, for space_
  Retention retention_;
  RecordedFiles recorded_;  // this run's finished files still kept
  std::string refusal_;
  std::vector<char> record_buffer_;                   // the open recording's buffer, allocated once
  std::unique_ptr<ZstdStreamCompressor> compressor_;  // output.pcap_compression = "zstd"
  PcapWriter writer_;                                 // reused for every recording
  PcapWriter* pcap_ = nullptr;                        // &writer_ while a recording is open
  std::string final_path_, part_path_;
  std::array<char, 128> unrecordable_{};  // a packet pcap cannot hold, said
  std::string sidecar_path_, sidecar_temporary_;
  OutputFile sidecar_file_;
  bool directory_synced_ = false;  // the open recording's name is on the disk
  std::int64_t opened_monotonic_ns_ = 0;
  std::uint64_t next_index_ = 0;  // the next recording's number (continues across runs)
  std::uint64_t packets_written_ = 0, packets_not_written_ = 0, packets_lost_ = 0;
  std::uint64_t bytes_closed_ = 0;  // in finished files; the open one adds its own
};

}  // namespace pandarcap
