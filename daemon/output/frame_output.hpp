// Frames as PCD files: DIR/frames/frame_<N>_<UTC start>[_partial].pcd.
//
// Each frame is written as frames/.<name>.tmp and renamed into place without replacing anything
// (a taken name becomes "_dupN", counted), so a reader never sees half a frame; a failed write
// removes the temporary file and is counted (OutputAccounting). The rename is the finisher
// thread's (daemon/output/file_finisher.hpp), after it synced the frame's data, and the
// directory is synced after it: a frame has its final name only once it is on the disk whole,
// and is counted written (frames_written, retention, its latency) then. A frame is not written
// while its file system is down to the space kept for the health files (HealthRoom: counted as a
// failed write, said in the health), and a frames/ removed while running is made again. N continues
// across runs: it starts after the highest number found at start-up (adopt_earlier_files), and is
// that base plus the frame's sequence number. Retention (frames_max_files / frames_max_bytes)
// counts earlier runs' frames too.
//
// With output.pcd_compression = "lzf" a frame is compressed whole (DATA binary_compressed,
// core/frames/pcd_compressed.hpp) before it is written, in buffers sized at start-up for the
// largest frame (arenas.points_per_frame).
//
// The points come encoded in the output layout (the decode worker wrote them into the arena so):
// a frame is its header and the arena's bytes. Uncompressed, they go past the page cache
// (O_DIRECT) where the file system allows it: the header is padded to 4096 bytes with a comment
// line, so the page-aligned arena's whole blocks go to the disk without a copy, and only the
// last partial block through the page cache. That halves the writer's kernel time per frame
// (docs/performance.md). Once warm, writing a frame allocates nothing: the names, header and
// LZF buffers are reused
// (retention, when on, lists one name per file). Owned by the writer thread.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "core/frames/pcd_compressed.hpp"
#include "core/health/latency_histogram.hpp"
#include "daemon/io/file_output.hpp"
#include "daemon/output/file_finisher.hpp"
#include "daemon/output/health_room.hpp"
#include "daemon/output/output_accounting.hpp"
#include "daemon/output/retention.hpp"
#include "daemon/output/writer_options.hpp"
#include "daemon/pipeline_types.hpp"

namespace pandarcap {

class FrameOutput {
 public:
  FrameOutput(const WriterOptions& options, OutputAccounting& accounting, HealthRoom& space,
              FileFinisher& finisher);

  const std::filesystem::path& directory() const noexcept { return dir_; }
  // At start-up, after the leftovers are cleaned: earlier runs' frames numbered and listed for
  // retention. Then the buffers are sized, so the first frames do not allocate either.
  void adopt_earlier_files();
  void reserve();

  // Writes the arena's frame and hands it to the finisher; a failure is counted, never thrown.
  void write(const FrameArena& arena);
  // The finisher's word on a frame: in place (counted written), or why not (a write error).
  void finished(const FinishJob& job);
  // Its retention list: the writer hears of each removal (the upload backlog counts it).
  Retention& retention() noexcept { return retention_; }
  // A frame removed by the free-space floor (space_floor.hpp): off the retention list.
  void removed_for_space(std::string_view path) noexcept { retention_.forget(path); }

  std::uint64_t frames_written() const noexcept { return frames_written_; }
  std::uint64_t bytes_written() const noexcept { return bytes_written_; }
  // Kernel receive time of the packet that completed a frame -> its file in place.
  const LatencyHistogram& latency() const noexcept { return latency_; }

 private:
  OutputAccounting& accounting_;
  HealthRoom& space_;
  FileFinisher& finisher_;
  std::filesystem::path dir_;
  int volume_;  // dir_'s file system, for space_
  Retention retention_;
  PcdFormat format_;
  bool lzf_;
  std::size_t max_frame_points_;
  std::uint64_t number_base_ = 0;  // + the frame's sequence = its file number
  std::uint64_t frames_written_ = 0, bytes_written_ = 0;
  LatencyHistogram latency_;
  PcdCompressor compressor_;  // lzf_: sized by reserve()
  std::string path_, temporary_path_, pcd_header_, refusal_;
  OutputFile file_;
  // O_DIRECT: the header's block (page-aligned, as the arenas are); cleared for good once a
  // file system refused a direct write.
  io::IoError write_direct(std::span<const std::uint8_t> rows);
  alignas(kDirectIoBlock) std::array<std::uint8_t, kDirectIoBlock> header_block_{};
  bool direct_works_ = true;
};

}  // namespace pandarcap
