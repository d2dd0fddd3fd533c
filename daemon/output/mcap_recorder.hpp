// Frames, health and (optionally) raw packets as MCAP files, the format Foxglove opens and
// `ros2 bag play` replays: DIR/mcap/pandarcap_<UTC first message>_<N>.mcap.
//
// Per file (daemon/mcap/mcap_file.hpp): one sensor_msgs/msg/PointCloud2 per frame on the points
// topic (the PCD files' points, byte for byte), the health record of every second as JSON on the
// health topic, with output.mcap_packets each datagram as pandar_msgs/msg/PandarPacket on the
// packets topic, the calibration in use as the attachment calibration.csv, and a metadata record
// "pandarcap" (version, sensor, decoder). Message log times are receive times (CLOCK_REALTIME)
// for live sources and the capture's times for replays, so a file plays back at the pace it was
// recorded; a PointCloud2's header.stamp is its first firing time by the sensor's clock.
//
// As with the pcap: written as NAME.mcap.part and renamed (never over anything) when finished, by
// the finisher thread once its data is synced (daemon/output/file_finisher.hpp), and synced
// while open every output.sync_interval_seconds (sync_open_file()); a
// new file at mcap_rotate_bytes / mcap_rotate_seconds, on SIGHUP, when a file's chunk index is
// full, and at the end (a rotation never waits for the disk: the file left finishes while the
// next one is written, McapFile::close_later, and is put in place once its tail is written);
// retention (mcap_max_files / mcap_max_bytes) counts earlier runs' files; N continues across runs;
// a leftover .part is finished at the next start (daemon/mcap/mcap_recovery.hpp). A failed write
// cuts the file back to its last whole chunk, finishes it there (its tail from the summary of
// those chunks, never by reading the file back on the writer thread), and counts the messages lost
// (mcap_messages_not_written, write_errors); the next message starts a new file. Owned by the
// writer thread; buffers are allocated in prepare(), so recording a message allocates nothing;
// starting a file allocates only its name's time stamp (as the pcap's does) and, with retention on,
// its entry in the retention list.
//
// As the pcap's: nothing is written while mcap/'s file system is down to the space kept for the
// health files (HealthRoom; counted as not written), mcap/ removed while running is made again,
// and messages in a file that vanished are counted as lost (messages_lost), the open file's at
// every flush, this run's finished files' at the end (verify_on_disk).
#pragma once

#include <cstdint>
#include <exception>
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>
#include <utility>

#include "daemon/mcap/mcap_file.hpp"
#include "daemon/output/file_finisher.hpp"
#include "daemon/output/health_room.hpp"
#include "daemon/output/output_accounting.hpp"
#include "daemon/output/retention.hpp"
#include "daemon/output/writer_options.hpp"
#include "daemon/pipeline_types.hpp"

namespace pandarcap {

class McapRecorder {
 public:
  // `options` must outlive the recorder.
  McapRecorder(const WriterOptions& options, OutputAccounting& accounting, HealthRoom& space,
               FileFinisher& finisher);
  ~McapRecorder();

  const std::filesystem::path& directory() const noexcept { return dir_; }
  // At start-up, after the leftovers are finished: earlier runs' files numbered and listed for
  // retention; then the buffers are allocated.
  void adopt_earlier_files();
  void prepare();

  // Each records one message (or a batch's); failures are counted, never thrown.
  void write_frame(const FrameArena& arena);
  void write_packets(const RawBatch& batch);
  void write_health(std::string_view json_line, std::int64_t realtime_ns);
  // Hands the open chunk to the compression thread and writes those compressed since: the file
  // on disk about a second behind. Never waits.
  void flush();
  // The same, then waits for every chunk in flight and writes it (at the end, before the final
  // health record, so that record counts every message).
  void drain();
  // Finishes the open file (if any), and one still closing, waiting for both; the next message
  // starts a new file.
  void close();
  // SIGHUP: the open file finished, without waiting for its chunks in flight (close_later).
  void rotate();
  // The open file's data synced, off this thread (output.sync_interval_seconds).
  void sync_open_file();
  // The finisher's word on a file.
  void finished(const FinishJob& job);

  // This run's finished files no longer on disk: their messages counted as lost. At the end.
  void verify_on_disk();
  // Its retention list: the writer hears of each removal (the upload backlog counts it).
  Retention& retention() noexcept { return retention_; }
  // A finished file of ours removed by the free-space floor (space_floor.hpp): removed on
  // purpose, as retention's are, so not counted as lost.
  void removed_for_space(std::string_view path) noexcept {
    retention_.forget(path);
    recorded_.forget(path);
  }

  // Every message written (monotonic); those on disk are messages_written() - messages_lost().
  std::uint64_t messages_written() const noexcept;
  std::uint64_t messages_not_written() const noexcept { return messages_not_written_; }
  std::uint64_t messages_lost() const noexcept { return messages_lost_; }
  // Left out because the compression thread was behind (every chunk buffer in flight).
  std::uint64_t messages_not_recorded() const noexcept {
    return file_ ? file_->messages_not_recorded() : 0;
  }
  std::uint64_t bytes_written() const noexcept;
  // Chunks stored uncompressed because the compression thread was a chunk behind.
  std::uint64_t chunks_uncompressed() const noexcept {
    return file_ ? file_->chunks_uncompressed() : 0;
  }

 private:
  // The file to write a message of `log_time` and about `bytes` to: rotated when due, opened when
  // none is; false (counted by the caller) when none can be, or space is short.
  bool ready(std::uint64_t log_time, std::uint64_t bytes);
  // The open file is no longer at its path: its messages are lost, the file let go.
  void lose_open_file();
  void failed(const std::exception& error);
  // Starts finishing the open file without waiting for its chunks in flight (a rotation): it
  // moves to closing_part_ / closing_final_ and is put in place by settle_closed(). A file still
  // closing from the rotation before is waited for first.
  void close_later();
  // The closing file, once done (its tail written, or its failure met): put in place, or left
  // as a .part for the next start when even its tail could not be written. Never waits.
  void settle_closed();
  // The same, after waiting for the closing file's chunks.
  void wait_closed();
  // A file done with, holding `messages` in whole chunks: put in place when `finished` (its tail
  // written: McapFile::abandon, McapClosedFile), else left as a .part for the next start's
  // recovery, its messages counted as written all the same.
  void settle_part(const std::string& part, const std::string& final_path, std::uint64_t messages,
                   bool finished);
  // The finished `part` holding `messages`: handed to the finisher to be put in place under its
  // final name `final_path`, counted (listed for retention once in place); removed when it holds
  // none. Throws std::system_error.
  void place_finished(const std::string& part, const std::string& final_path,
                      std::uint64_t messages);
  // The size of the file `path` (0 when it cannot be asked).
  static std::uint64_t part_bytes(const std::string& path) noexcept;

  const WriterOptions& options_;
  OutputAccounting& accounting_;
  HealthRoom& space_;
  FileFinisher& finisher_;
  std::filesystem::path dir_;
  int volume_;  // dir_'s file system, for space_
  Retention retention_;
  RecordedFiles recorded_;  // this run's finished files still kept
  std::string refusal_;
  std::unique_ptr<McapFile> file_;
  std::string final_path_, part_path_;
  std::string closing_final_, closing_part_;  // the file close_later() left, until placed
  bool directory_synced_ = false;             // the open file's name is on the disk
  std::int64_t opened_monotonic_ns_ = 0;
  std::uint64_t next_index_ = 0;
  std::uint64_t last_log_time_ = 0;  // of the latest frame or packet: replays' health times
  std::uint64_t messages_closed_ = 0, messages_not_written_ = 0, messages_lost_ = 0;
  std::uint64_t bytes_closed_ = 0;
};

}  // namespace pandarcap
