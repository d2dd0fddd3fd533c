#include "daemon/output/frame_output.hpp"

#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <iterator>
#include <span>

#include "core/frames/pcd.hpp"
#include "core/utc_time.hpp"
#include "daemon/clocks.hpp"
#include "daemon/output/output_directories.hpp"
#include "daemon/output/output_leftovers.hpp"

namespace pandarcap {
FrameOutput::FrameOutput(const WriterOptions& options, OutputAccounting& accounting,
                         HealthRoom& space, FileFinisher& finisher)
    : accounting_(accounting),
      space_(space),
      finisher_(finisher),
      dir_(options.output_dir / "frames"),
      volume_(space.watch(dir_)),
      retention_(options.frames_max_files, options.frames_max_bytes),
      format_(options.pcd_format),
      lzf_(options.pcd_lzf),
      max_frame_points_(options.max_frame_points) {}

void FrameOutput::adopt_earlier_files() {
  number_base_ = adopt_earlier_frames(dir_, retention_);
}

void FrameOutput::reserve() {
  path_.reserve(4096);
  temporary_path_.reserve(4096);
  file_.reserve_path(4096);
  // Room for the header padded to a direct write's block (pad_pcd_header): the first frame
  // written after the warm-up (a sensor that starts after the daemon) must not grow it.
  pcd_header_.reserve(kDirectIoBlock);
  refusal_.reserve(1024);  // a refused write's reason (HealthRoom::allows) at any moment
  retention_.reserve(dir_.native().size() + 96);  // frame_<N>_<UTC>[_partial][_dupN].pcd
  if (lzf_) compressor_.reserve(max_frame_points_, format_.layout);
}

void FrameOutput::write(const FrameArena& arena) {
  const Frame& frame = arena.frame;
  // The decode worker encoded the points in this layout already (the arenas are made with it).
  const std::span<const std::uint8_t> rows = frame.used_bytes();
  pcd_header_.clear();
  append_pcd_header(pcd_header_, frame.size, format_.layout, frame.info.start_ns,
                    lzf_ ? PcdData::kBinaryCompressed : PcdData::kBinary);
  std::span<const std::uint8_t> data = rows;
  if (lzf_) {
    try {
      data = compressor_.compress_rows(rows, format_.layout);
    } catch (const std::exception& error) {
      accounting_.write_failed(error, 0);
      return;
    }
  }
  // Uncompressed frames go past the page cache when the file system allows it: the header is
  // padded to one block, so the points start page-aligned in the file as in the arena.
  const bool direct = !lzf_ && rows.size() >= kDirectIoBlock;
  const std::uint64_t expected =
      (direct ? std::max(kDirectIoBlock, pcd_header_.size()) : pcd_header_.size()) + data.size();
  // frames/frame_000123_20261122T120000.123Z[_partial].pcd, written as frames/.<name>.tmp.
  path_.assign(dir_.native());
  fmt::format_to(std::back_inserter(path_), "/frame_{:06}_", number_base_ + frame.info.sequence);
  append_utc_file_stamp(path_, frame.info.start_ns, true);
  path_ += frame.info.partial ? "_partial.pcd" : ".pcd";
  assign_temporary_name(temporary_path_, path_);
  if (!space_.allows(volume_, expected, refusal_)) {
    accounting_.write_failed(refusal_, expected);
    return;
  }
  // Failures come back as codes, not exceptions: a full disk fails every frame, and counting
  // one allocates nothing.
  const bool try_direct = direct && direct_works_ && pad_pcd_header(pcd_header_, kDirectIoBlock);
  io::IoError error = open_in_directory(
      file_, temporary_path_,
      try_direct ? OutputFile::Mode::kCreateDirect : OutputFile::Mode::kCreate, dir_);
  if (!error) {
    if (file_.direct()) {
      error = write_direct(rows);
    } else {
      error = file_.try_write(pcd_header_);
      if (!error) error = file_.try_write(data);
    }
  }
  if (!error) error = file_.try_close();
  if (error) {
    (void)file_.try_close();  // the error said already; its path stays readable (file_.path())
    ::unlink(temporary_path_.c_str());
    accounting_.write_failed(error, expected);
    return;
  }
  finisher_.place(
      FinishOwner::kFrames, temporary_path_, path_,
      {.bytes = file_.size(), .stamp_ns = arena.completed_receive_ns, .remove_on_failure = true});
}

void FrameOutput::finished(const FinishJob& job) {
  if (job.name_taken) accounting_.name_collision(job.from, job.to);
  if (job.placed) {
    ++frames_written_;
    bytes_written_ += job.bytes;
    // Until the finisher put it in place, not until this thread heard of it.
    if (job.stamp_ns > 0) latency_.record(job.done_realtime_ns - job.stamp_ns);
    retention_.add(job.to, job.bytes);
  }
  // Not on the disk whole (its temporary file removed), or in place but its name not synced.
  if (job.failed) accounting_.write_failed(job.error_text(), job.placed ? 0 : job.bytes);
}

io::IoError FrameOutput::write_direct(std::span<const std::uint8_t> rows) {
  // The padded header is exactly one block; it is copied where O_DIRECT can take it from.
  std::copy(pcd_header_.begin(), pcd_header_.end(), header_block_.begin());
  const std::span<const std::uint8_t> header(header_block_);
  const std::size_t whole = rows.size() / kDirectIoBlock * kDirectIoBlock;
  io::IoError error = file_.try_write(header);
  if (!error) error = file_.try_write(rows.first(whole));
  if (error) {
    // A file system that opens with O_DIRECT but refuses the writes: the page cache, for the
    // rest of this frame (from where it stopped) and for every frame after it.
    if (error.code != EINVAL) return error;
    direct_works_ = false;
  }
  file_.end_direct();
  if (file_.size() == 0) {
    if (const io::IoError header_error = file_.try_write(header)) return header_error;
  }
  return file_.try_write(rows.subspan(file_.size() - kDirectIoBlock));  // the tail, or the rest
}

}  // namespace pandarcap
