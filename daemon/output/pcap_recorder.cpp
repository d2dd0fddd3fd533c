#include "daemon/output/pcap_recorder.hpp"

#include <arpa/inet.h>
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cerrno>
#include <span>
#include <stdexcept>
#include <string_view>
#include <system_error>
#include <utility>

#include "core/utc_time.hpp"
#include "daemon/clocks.hpp"
#include "daemon/io/file_output.hpp"
#include "daemon/io/text_file.hpp"
#include "daemon/output/output_directories.hpp"
#include "daemon/output/output_leftovers.hpp"
#include "daemon/output/rotation.hpp"
#include "daemon/pcap/recording_sidecars.hpp"

namespace pandarcap {
PcapRecorder::PcapRecorder(const WriterOptions& options, OutputAccounting& accounting,
                           HealthRoom& space, FileFinisher& finisher)
    : options_(options),
      accounting_(accounting),
      space_(space),
      finisher_(finisher),
      dir_(options.output_dir / "raw"),
      volume_(space.watch(dir_)),
      retention_(options.pcap_max_files, options.pcap_max_bytes),
      record_buffer_(kPcapBufferBytes),
      compressor_(options.pcap_zstd ? std::make_unique<ZstdStreamCompressor>(
                                          kPcapBufferBytes, options.pcap_zstd_level)
                                    : nullptr) {}

PcapRecorder::~PcapRecorder() = default;

void PcapRecorder::adopt_earlier_files() {
  next_index_ = adopt_earlier_recordings(dir_, retention_);
  // The lists and names made at their size now: the first recording finished after the warm-up
  // allocates nothing (pandarcap_<UTC>_<N>[_dupN].pcap.zst and its sidecars: under 96 bytes).
  const std::size_t path_bytes = dir_.native().size() + 96;
  retention_.reserve(path_bytes);
  recorded_.reserve(kRecordedFilesReserved, path_bytes);
  refusal_.reserve(1024);  // a refused write's reason (HealthRoom::allows) at any moment
  for (std::string* name : {&final_path_, &part_path_, &sidecar_path_, &sidecar_temporary_})
    name->reserve(path_bytes);
  writer_.reserve_path(path_bytes);
  sidecar_file_.reserve_path(path_bytes);
}

void PcapRecorder::save_calibration(std::string_view csv) {
  // The angles the recordings are decoded with travel with them.
  const std::filesystem::path current = dir_ / "calibration.csv";
  const TextFile earlier = read_text_file(current.string());
  if (earlier.status == TextFile::Status::kOk && earlier.text != csv) {
    std::string kept = (dir_ / fmt::format("calibration_before_{:04}.csv", next_index_)).native();
    accounting_.put_in_place(current.native(), kept);
    spdlog::info("{}: the calibration of earlier recordings differs from this run's; kept as {}",
                 current.string(), std::filesystem::path(kept).filename().string());
  }
  write_file_durably(current, csv);
}

void PcapRecorder::save_sensor_info(std::string_view json) {
  write_file_durably(dir_ / "sensor.json", json);
}

std::uint64_t PcapRecorder::bytes_written() const noexcept {
  return bytes_closed_ + (pcap_ ? pcap_->bytes() : 0);
}

io::IoError PcapRecorder::open(std::int64_t first_packet_ns) {
  // The number is taken only by a recording that opens: a disk that refuses every open (read-only)
  // does not make the numbers climb. The names are made in strings that keep their memory.
  final_path_.assign(dir_.native());
  final_path_ += "/pandarcap_";
  append_utc_file_stamp(final_path_, first_packet_ns, false);
  fmt::format_to(std::back_inserter(final_path_), "_{:04}.pcap{}", next_index_,
                 compressor_ ? ".zst" : "");
  part_path_.assign(final_path_);
  part_path_ += ".part";
  io::IoError error = writer_.open(part_path_, record_buffer_, compressor_.get());
  if (error.code == ENOENT && make_again_if_removed(dir_)) {
    error = writer_.open(part_path_, record_buffer_, compressor_.get());
  }
  if (error) {
    // Created but not even its header written (a full disk): not left behind, one per attempt.
    ::unlink(part_path_.c_str());
    return error;
  }
  pcap_ = &writer_;
  ++next_index_;
  directory_synced_ = false;
  opened_monotonic_ns_ = monotonic_ns();
  return {};
}

void PcapRecorder::close() {
  if (!pcap_) return;
  if (!pcap_->at_its_path()) {
    lose_open_file();
    return;
  }
  // close() flushes first; a failing flush leaves the file open, to be cut back to whole records
  // by abandon().
  if (const io::IoError error = pcap_->try_close()) {
    abandon(error, 0);
    return;
  }
  finish_file();
}

void PcapRecorder::rotate() {
  const std::string_view name =
      std::string_view(final_path_).substr(final_path_.rfind('/') + 1);  // npos + 1: all of it
  spdlog::info("SIGHUP: closing {} and starting new recordings",
               pcap_ ? name : std::string_view("no open pcap"));
  close();
}

void PcapRecorder::flush() {
  if (!pcap_) return;
  if (!pcap_->at_its_path()) {
    lose_open_file();
    return;
  }
  if (const io::IoError error = pcap_->try_flush()) abandon(error, 0);
}

void PcapRecorder::lose_open_file() {
  // Whatever it holds, and what waits in its buffer, reaches no reader.
  const std::uint64_t flushed = pcap_->flushed_records();
  const PcapWriter::Dropped dropped = pcap_->abandon();
  packets_lost_ += flushed + dropped.records;
  bytes_closed_ += pcap_->flushed_bytes();
  spdlog::warn(
      "{} is gone (removed, or its directory replaced): its {} packets are lost; the "
      "next packets start a new recording",
      pcap_->path(), flushed + dropped.records);
  pcap_ = nullptr;
}

void PcapRecorder::verify_on_disk() {
  const RecordedFiles::Gone gone = recorded_.take_gone();
  if (gone.files == 0) return;
  if (options_.upload) {
    // raw/ is an upload directory: a finished recording that left it was moved by the upload
    // (which never takes one before it is finished), not lost.
    spdlog::info("{} of this run's recordings have left {} for the upload ({} packets)", gone.files,
                 dir_.string(), gone.items);
    return;
  }
  packets_lost_ += gone.items;
  spdlog::warn(
      "{} of this run's recordings are gone from {} (removed while running): their {} "
      "packets are not counted as recorded",
      gone.files, dir_.string(), gone.items);
}

template <class Error>
void PcapRecorder::abandon(const Error& error, std::uint64_t failed_bytes) {
  // The records buffered since the last good flush never reached the file whole: they are taken
  // back from the recorded count (which no health record has reported yet: every tick flushes
  // first) and counted as not written, with the record being written when it failed.
  const PcapWriter::Dropped dropped = pcap_->abandon();
  packets_written_ -= dropped.records;
  packets_not_written_ += dropped.records;
  accounting_.write_failed(error, dropped.bytes + failed_bytes);
  finish_file();
}

void PcapRecorder::finish_file() {
  const std::string& part = pcap_->path();
  if (pcap_->flushed_records() == 0) {
    // Not even one record: nothing worth keeping.
    if (::unlink(part.c_str()) != 0 && errno != ENOENT) {
      accounting_.write_failed(io::IoError{errno, "cannot remove", part}, 0);
    }
    pcap_ = nullptr;
    return;
  }
  bytes_closed_ += pcap_->flushed_bytes();
  write_sidecars();
  finisher_.place(FinishOwner::kRecordings, part, final_path_,
                  {.bytes = pcap_->flushed_bytes(), .items = pcap_->flushed_records()});
  pcap_ = nullptr;
}

void PcapRecorder::write_sidecars() {
  // DIR/STEM.pcap[.zst] -> DIR/STEM.calibration.csv, DIR/STEM.sensor.json (recording_sidecars.hpp)
  const std::string_view stem = recording_stem(final_path_).value_or(final_path_);
  const auto stem_end = static_cast<std::size_t>(stem.data() - final_path_.data()) + stem.size();
  const std::string_view texts[] = {options_.calibration_csv, options_.sensor_json};
  static_assert(std::size(texts) == kSidecarSuffixes.size());
  for (std::size_t i = 0; i < kSidecarSuffixes.size(); ++i) {
    const std::string_view text = texts[i];
    if (text.empty()) continue;
    sidecar_path_.assign(final_path_, 0, stem_end);
    sidecar_path_ += kSidecarSuffixes[i];
    assign_temporary_name(sidecar_temporary_, sidecar_path_);
    if (!space_.allows(volume_, text.size(), refusal_)) {
      accounting_.write_failed(refusal_, text.size());
      continue;
    }
    io::IoError error = sidecar_file_.try_open(sidecar_temporary_, OutputFile::Mode::kCreate);
    if (!error) error = sidecar_file_.try_write(text);
    if (!error) error = sidecar_file_.try_close();
    if (error) {
      (void)sidecar_file_.try_close();
      ::unlink(sidecar_temporary_.c_str());
      accounting_.write_failed(error, text.size());
      continue;
    }
    finisher_.place(FinishOwner::kSidecars, sidecar_temporary_, sidecar_path_,
                    {.bytes = text.size(), .remove_on_failure = true});
  }
}

void PcapRecorder::sync_open_file() {
  if (pcap_) finisher_.sync(FinishOwner::kRecordings, pcap_->path(), directory_synced_);
}

void PcapRecorder::finished(const FinishJob& job) {
  if (job.name_taken) accounting_.name_collision(job.from, job.to);
  const bool recording = job.owner == FinishOwner::kRecordings;
  if (recording && job.kind == FinishJob::Kind::kPlace && job.placed) {
    retention_.add(job.to, job.bytes);
    recorded_.add(job.to, job.items, retention_);
  }
  if (!job.failed) return;
  // A recording that went while open is counted lost at its next flush (lose_open_file).
  if (job.kind == FinishJob::Kind::kSync && job.error_code == ENOENT) return;
  accounting_.write_failed(job.error_text(), 0);
  if (recording && job.kind == FinishJob::Kind::kPlace && !job.placed) {
    // Not known to be on the disk: not counted as recorded. What did reach it stays as the
    // .part, which the next start finishes.
    packets_lost_ += job.items;
    spdlog::warn("{}: not put in place ({}); its {} packets are not counted as recorded", job.from,
                 job.error_text(), job.items);
  }
}

void PcapRecorder::write(const RawBatch& batch) {
  // The batch as the file would take it: a record header and synthesised headers per packet.
  std::uint64_t batch_bytes = 0;
  for (std::size_t i = 0; i < batch.size; ++i)
    batch_bytes +=
        batch.packets[i].length +
        (batch.packets[i].wire_header_length > 0
             ? kPcapRecordHeaderBytes + batch.packets[i].wire_header_length +
                   batch.packets[i].wire_trailer_length
         : batch.packets[i].source.v4.sin_family == AF_INET6 ? kPcapRecordOverheadBytesIpv6
                                                             : kPcapRecordOverheadBytes);
  if (batch.size > 0 && !space_.allows(volume_, batch_bytes, refusal_)) {
    packets_not_written_ += batch.size;
    accounting_.write_failed(refusal_, batch_bytes);
    return;
  }
  bool failed = false;  // the disk failed on this batch: the rest is not tried (counted)
  for (std::size_t i = 0; i < batch.size; ++i) {
    const RawPacket& packet = batch.packets[i];
    if (failed) {
      ++packets_not_written_;
      accounting_.not_written(packet.length);
      continue;
    }
    if (!PcapWriter::recordable(packet.length, packet.receive_time_ns)) {
      // This packet cannot be recorded (a time outside what pcap can hold); the file is fine.
      ++packets_not_written_;
      const auto said = fmt::format_to_n(
          unrecordable_.data(), unrecordable_.size(),
          "a packet of {} bytes received at {} ns cannot be recorded in pcap (1970 to 2106)",
          packet.length, packet.receive_time_ns);
      accounting_.write_failed(
          std::string_view(unrecordable_.data(), std::min(said.size, unrecordable_.size())),
          packet.length);
      continue;
    }
    try {
      if (pcap_ && rotation_due(pcap_->bytes(), opened_monotonic_ns_, options_.pcap_rotate_bytes,
                                options_.pcap_rotate_seconds)) {
        close();
      }
      io::IoError error = pcap_ ? io::IoError{} : open(packet.receive_time_ns);
      if (!error) {
        if (packet.wire_header_length > 0) {
          error = pcap_->try_write_frame(
              {packet.wire_header, packet.wire_header_length},
              {packet.payload, std::size_t{packet.length} + packet.wire_trailer_length},
              packet.wire_length, packet.receive_time_ns);
        } else {
          error = pcap_->try_write(std::span<const std::uint8_t>(packet.payload, packet.length),
                                   packet.original_length, packet.receive_time_ns,
                                   to_endpoint(packet.source), to_endpoint(packet.destination));
        }
      }
      if (!error) {
        ++packets_written_;
        continue;
      }
      // A failing file is cut back to its whole records and closed. The next batch starts a new
      // one (and fails again, counted, while the disk stays full): at most one attempt per
      // batch, not one per packet.
      ++packets_not_written_;
      if (pcap_) {
        abandon(error, packet.length);
      } else {
        accounting_.write_failed(error, packet.length);  // the file could not even be created
      }
      failed = true;
    } catch (const std::exception& error) {
      // Not the disk (a compressor's error, none expected): counted the same way.
      ++packets_not_written_;
      if (pcap_) {
        abandon(error, packet.length);
      } else {
        accounting_.write_failed(error, packet.length);
      }
      failed = true;
    }
  }
  // Each batch reaches the file whole: a crash loses at most the batch being written.
  flush();
}

}  // namespace pandarcap
