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
// As with the pcap: written as NAME.mcap.part and renamed (never over anything) when finished; a
// new file at mcap_rotate_bytes / mcap_rotate_seconds, on SIGHUP, when a file's chunk index is
// full, and at the end; retention (mcap_max_files / mcap_max_bytes) counts earlier runs' files;
// N continues across runs; a leftover .part is finished at the next start
// (daemon/mcap/mcap_recovery.hpp). A failed write cuts the file back to its last whole chunk,
// finishes it there, and counts the messages lost (mcap_messages_not_written, write_errors); the
// next message starts a new file. Owned by the writer thread; buffers are allocated in prepare(),
// so recording a message allocates nothing; starting a file allocates only its name's time stamp
// (as the pcap's does) and, with retention on, its entry in the retention list.
#pragma once

#include <cstdint>
#include <exception>
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>

#include "daemon/mcap/mcap_file.hpp"
#include "daemon/output/output_accounting.hpp"
#include "daemon/pipeline_types.hpp"
#include "daemon/output/retention.hpp"
#include "daemon/output/writer_options.hpp"

namespace pandarcap {

class McapRecorder {
 public:
  // `options` must outlive the recorder.
  McapRecorder(const WriterOptions& options, OutputAccounting& accounting);
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
  // Writes the open chunk: the file on disk at most a second behind.
  void flush();
  // Finishes the open file (if any); the next message starts a new one.
  void close();
  // SIGHUP: the open file finished.
  void rotate();

  std::uint64_t messages_written() const noexcept;
  std::uint64_t messages_not_written() const noexcept { return messages_not_written_; }
  std::uint64_t bytes_written() const noexcept;

 private:
  // The file to write a message of `log_time` to: rotated when due, opened when none is.
  bool ready(std::uint64_t log_time);
  void failed(const std::exception& error);
  void finish_file();
  // The finished .part holding `messages`: put in place under its final name, counted and listed
  // for retention (removed when it holds none). Throws std::system_error.
  void place_finished(std::uint64_t messages);

  const WriterOptions& options_;
  OutputAccounting& accounting_;
  std::filesystem::path dir_;
  Retention retention_;
  std::unique_ptr<McapFile> file_;
  std::string final_path_, part_path_;
  std::int64_t opened_monotonic_ns_ = 0;
  std::uint64_t next_index_ = 0;
  std::uint64_t last_log_time_ = 0;  // of the latest frame or packet: replays' health times
  std::uint64_t messages_closed_ = 0, messages_not_written_ = 0, bytes_closed_ = 0;
};

}  // namespace pandarcap
