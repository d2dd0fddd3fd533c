#include "daemon/output/mcap_recorder.hpp"

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <span>
#include <system_error>

#include "core/utc_time.hpp"
#include "daemon/clocks.hpp"
#include "daemon/io/file_output.hpp"
#include "daemon/output/output_directories.hpp"
#include "daemon/output/output_leftovers.hpp"
#include "daemon/output/rotation.hpp"

namespace pandarcap {
namespace {

// For the space a message asks for: a message's record, chunk and index bytes besides its data,
// generously.
constexpr std::uint64_t kMcapMessageOverheadBytes = 128;

}  // namespace

McapRecorder::McapRecorder(const WriterOptions& options, OutputAccounting& accounting,
                           HealthRoom& space, FileFinisher& finisher)
    : options_(options),
      accounting_(accounting),
      space_(space),
      finisher_(finisher),
      dir_(options.output_dir / "mcap"),
      volume_(space.watch(dir_)),
      retention_(options.mcap_max_files, options.mcap_max_bytes) {}

McapRecorder::~McapRecorder() = default;

void McapRecorder::adopt_earlier_files() {
  next_index_ = adopt_earlier_mcap_files(dir_, retention_);
  // The lists made at their size now: the first file finished after the warm-up allocates
  // nothing (pandarcap_<UTC>_<N>[_dupN].mcap: under 96 bytes).
  const std::size_t path_bytes = dir_.native().size() + 96;
  retention_.reserve(path_bytes);
  recorded_.reserve(kRecordedFilesReserved, path_bytes);
  for (std::string* path : {&final_path_, &part_path_, &closing_final_, &closing_part_})
    path->reserve(path_bytes);
  refusal_.reserve(1024);  // a refused write's reason (HealthRoom::allows) at any moment
}

void McapRecorder::prepare() {
  McapFileOptions o = options_.mcap_file;
  o.library = fmt::format("pandarcap {}", options_.version);
  o.metadata = {{"version", options_.version},
                {"sensor_name", options_.sensor_name},
                {"decoder", options_.decoder},
                // The model known at start ("" for a live "auto": the packets name it).
                {"sensor_model", options_.mcap_file.sensor_model},
                {"calibration_source", options_.sensor_identity.calibration_source},
                {"sensor_serial", options_.sensor_identity.serial},
                {"sensor_firmware", options_.sensor_identity.firmware},
                {"device_name", options_.device_name},
                {"config_hash", options_.config_hash},
                // The sensor facts, as raw/sensor.json holds them (identity, configuration,
                // where the calibration came from); the calibration itself is the attachment.
                {"sensor_json", options_.sensor_json}};
  o.device_name = options_.device_name;
  o.calibration_csv = options_.calibration_csv;
  file_ = std::make_unique<McapFile>(o);
  for (std::string* path : {&final_path_, &part_path_, &closing_final_, &closing_part_})
    path->reserve(4096);
}

std::uint64_t McapRecorder::messages_written() const noexcept {
  if (!file_) return messages_closed_;
  return messages_closed_ + (file_->is_open() ? file_->messages() : 0) + file_->closing_messages();
}

std::uint64_t McapRecorder::bytes_written() const noexcept {
  return bytes_closed_ + (file_ ? file_->bytes() + file_->closing_bytes() : 0);
}

bool McapRecorder::ready(std::uint64_t log_time, std::uint64_t bytes) {
  if (bytes > 0 && !space_.allows(volume_, bytes, refusal_)) {
    accounting_.write_failed(refusal_, bytes);
    return false;
  }
  settle_closed();
  if (file_->is_open() &&
      (file_->full() ||
       rotation_due(file_->bytes() + file_->bytes_in_flight(), opened_monotonic_ns_,
                    options_.mcap_rotate_bytes, options_.mcap_rotate_seconds))) {
    close_later();
  }
  if (file_->is_open()) return true;
  final_path_.assign(dir_.native());
  // The number is taken only by a file that opens (a read-only disk does not make it climb).
  final_path_ += "/pandarcap_";
  append_utc_file_stamp(final_path_, static_cast<std::int64_t>(log_time), false);
  fmt::format_to(std::back_inserter(final_path_), "_{:04}.mcap", next_index_);
  part_path_.assign(final_path_);
  part_path_ += ".part";
  try {
    try {
      file_->open(part_path_, static_cast<std::uint64_t>(realtime_ns()));
    } catch (const std::system_error& error) {
      if (error.code().value() != ENOENT || !make_again_if_removed(dir_)) throw;
      file_->abandon();
      file_->open(part_path_, static_cast<std::uint64_t>(realtime_ns()));
    }
  } catch (const std::exception& error) {
    // Created but not even its header written (a full disk): not left behind.
    file_->abandon();
    ::unlink(part_path_.c_str());
    accounting_.write_failed(error, 0);
    return false;
  }
  ++next_index_;
  directory_synced_ = false;
  opened_monotonic_ns_ = monotonic_ns();
  return true;
}

void McapRecorder::failed(const std::exception& error) {
  // The messages of the chunk being written are lost (counted, with their bytes as recorded);
  // what the file holds up to its last whole chunk is finished as a file readers accept (its
  // tail from the summary of those chunks: the file is not read back on this thread).
  const std::uint64_t kept = file_->messages();  // in whole chunks, on the disk
  const std::uint64_t lost_bytes = file_->bytes_not_in_file();
  bool finished = false;
  const std::uint64_t lost = file_->abandon(&finished);
  messages_not_written_ += lost;
  accounting_.write_failed(error, lost_bytes);
  settle_part(part_path_, final_path_, kept, finished);
  settle_closed();
}

void McapRecorder::settle_part(const std::string& part, const std::string& final_path,
                               std::uint64_t messages, bool finished) {
  if (finished) {
    try {
      place_finished(part, final_path, messages);
    } catch (const std::exception& error) {
      accounting_.write_failed(error, 0);
    }
    return;
  }
  // The disk refused even the tail: the .part stays, and the next start's recovery finishes it.
  // Its messages are written all the same: messages_written must neither fall back nor leave
  // them out.
  messages_closed_ += messages;
  bytes_closed_ += part_bytes(part);
  spdlog::warn("{}: left unfinished after a failed write; the next start finishes it", part);
}

void McapRecorder::write_frame(const FrameArena& arena) {
  const FrameInfo& info = arena.frame.info;
  const auto log_time = static_cast<std::uint64_t>(
      arena.completed_log_ns > 0 ? arena.completed_log_ns : info.start_ns);
  last_log_time_ = log_time;
  if (!ready(log_time, arena.frame.used_bytes().size())) {
    ++messages_not_written_;
    return;
  }
  try {
    file_->add_frame(arena.frame, log_time);
  } catch (const std::length_error& error) {
    ++messages_not_written_;  // cannot happen with arenas of the configured size
    accounting_.write_failed(error, 0);
  } catch (const std::exception& error) {
    ++messages_not_written_;
    failed(error);
  }
}

void McapRecorder::write_packets(const RawBatch& batch) {
  if (batch.size == 0) return;
  // Space is asked for once for the whole batch (a refusal counts one failed write).
  std::uint64_t batch_bytes = 0;
  for (std::size_t i = 0; i < batch.size; ++i)
    batch_bytes += batch.packets[i].length + kMcapMessageOverheadBytes;
  if (!space_.allows(volume_, batch_bytes, refusal_)) {
    accounting_.write_failed(refusal_, batch_bytes);
    messages_not_written_ += batch.size;
    last_log_time_ = static_cast<std::uint64_t>(batch.packets[batch.size - 1].receive_time_ns);
    return;
  }
  for (std::size_t i = 0; i < batch.size; ++i) {
    const RawPacket& packet = batch.packets[i];
    const auto log_time = static_cast<std::uint64_t>(packet.receive_time_ns);
    last_log_time_ = log_time;
    if (!ready(log_time, 0)) {
      messages_not_written_ += batch.size - i;  // the disk is failing: not tried per packet
      return;
    }
    try {
      file_->add_packet(std::span<const std::uint8_t>(packet.payload, packet.length),
                        packet.receive_time_ns, log_time);
    } catch (const std::exception& error) {
      messages_not_written_ += batch.size - i;
      failed(error);
      return;
    }
  }
}

void McapRecorder::write_health(std::string_view json_line, std::int64_t realtime) {
  // Replays stamp health with the recording's time, so the file stays one timeline; a record
  // from before the first packet has no place on it and describes nothing yet: not written.
  if (options_.mcap_replay_time && last_log_time_ == 0) return;
  const std::uint64_t log_time =
      options_.mcap_replay_time ? last_log_time_ : static_cast<std::uint64_t>(realtime);
  if (!ready(log_time, json_line.size() + kMcapMessageOverheadBytes)) {
    ++messages_not_written_;
    return;
  }
  try {
    file_->add_health(json_line, log_time);
  } catch (const std::exception& error) {
    ++messages_not_written_;
    failed(error);
  }
}

void McapRecorder::lose_open_file() {
  const std::uint64_t messages = file_->messages();
  // Those not yet in it (the open chunk, the chunks in flight) were never written. Its chunks
  // may wait behind a closing file's on a stalled disk: let go, not waited for.
  messages_not_written_ += file_->let_go();
  messages_closed_ += messages;  // written, and lost with the file: messages_written stays
  messages_lost_ += messages;
  spdlog::warn(
      "{} is gone (removed, or its directory replaced): its {} messages are lost; the "
      "next message starts a new file",
      part_path_, messages);
  settle_closed();
}

void McapRecorder::verify_on_disk() {
  const RecordedFiles::Gone gone = recorded_.take_gone();
  if (gone.files == 0) return;
  if (options_.upload) {
    // mcap/ is an upload directory: a finished file that left it was moved by the upload.
    spdlog::info("{} of this run's MCAP files have left {} for the upload ({} messages)",
                 gone.files, dir_.string(), gone.items);
    return;
  }
  messages_lost_ += gone.items;
  spdlog::warn(
      "{} of this run's MCAP files are gone from {} (removed while running): their {} "
      "messages are not counted as recorded",
      gone.files, dir_.string(), gone.items);
}

void McapRecorder::flush() {
  if (!file_) return;
  if (file_->is_open()) {
    if (!file_->at_its_path()) {
      lose_open_file();
      return;
    }
    try {
      file_->flush();
    } catch (const std::exception& error) {
      failed(error);
    }
  }
  settle_closed();
}

void McapRecorder::drain() {
  flush();
  if (!file_ || (!file_->is_open() && !file_->closing() && !file_->leaving())) return;
  try {
    file_->drain();  // the closing file's chunks too: it finishes
  } catch (const std::exception& error) {
    failed(error);
  }
  settle_closed();
}

void McapRecorder::close() {
  if (!file_) return;
  close_later();
  wait_closed();
}

void McapRecorder::close_later() {
  if (!file_->is_open()) return;
  if (!file_->at_its_path()) {
    lose_open_file();
    return;
  }
  // One file closes at a time: a rotation inside a stall that still holds the file before
  // waits here for it (McapFile::close_later).
  wait_closed();
  try {
    file_->close_later();
  } catch (const std::exception& error) {
    failed(error);
    return;
  }
  // Its names go with it (no allocation: both pairs are reserved alike); ready() names the next.
  closing_part_.swap(part_path_);
  closing_final_.swap(final_path_);
  settle_closed();
}

void McapRecorder::wait_closed() {
  if (!file_->closing()) return;
  file_->finish_closing();
  settle_closed();
}

void McapRecorder::settle_closed() {
  McapClosedFile closed;
  if (!file_ || !file_->take_closed(closed)) return;
  if (closed.error) {
    messages_not_written_ += closed.messages_lost;
    accounting_.write_failed(closed.error, closed.bytes_lost);
  }
  settle_part(closing_part_, closing_final_, closed.messages, closed.finished);
}

void McapRecorder::place_finished(const std::string& part, const std::string& final_path,
                                  std::uint64_t messages) {
  if (messages == 0) {
    ::unlink(part.c_str());  // nothing worth keeping
    return;
  }
  const std::uint64_t bytes = part_bytes(part);
  messages_closed_ += messages;
  bytes_closed_ += bytes;
  finisher_.place(FinishOwner::kMcap, part, final_path, {.bytes = bytes, .items = messages});
}

void McapRecorder::sync_open_file() {
  if (file_ && file_->is_open()) finisher_.sync(FinishOwner::kMcap, part_path_, directory_synced_);
}

void McapRecorder::finished(const FinishJob& job) {
  if (job.name_taken) accounting_.name_collision(job.from, job.to);
  if (job.kind == FinishJob::Kind::kPlace && job.placed) {
    retention_.add(job.to, job.bytes);
    recorded_.add(job.to, job.items, retention_);
  }
  if (!job.failed) return;
  // A file that went while open is counted lost at its next flush (lose_open_file).
  if (job.kind == FinishJob::Kind::kSync && job.error_code == ENOENT) return;
  accounting_.write_failed(job.error_text(), 0);
  if (job.kind == FinishJob::Kind::kPlace && !job.placed) {
    // Not known to be on the disk: not counted as recorded; the next start finishes the .part.
    messages_lost_ += job.items;
    spdlog::warn("{}: not put in place ({}); its {} messages are not counted as recorded", job.from,
                 job.error_text(), job.items);
  }
}

void McapRecorder::rotate() {
  if (!file_ || !file_->is_open()) return;
  const std::string_view name(final_path_);
  spdlog::info("SIGHUP: closing {}", name.substr(name.rfind('/') + 1));
  close_later();
}

std::uint64_t McapRecorder::part_bytes(const std::string& path) noexcept {
  // stat(2) on the held name: std::filesystem::file_size would build a path (allocations on the
  // writer's loop at every rotation).
  struct stat status {};
  return ::stat(path.c_str(), &status) == 0 ? static_cast<std::uint64_t>(status.st_size) : 0;
}

}  // namespace pandarcap
