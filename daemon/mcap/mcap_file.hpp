// One MCAP file being written (https://mcap.dev/spec; the records are core/mcap/).
//
// Messages collect in an uncompressed chunk in memory, one of a small pool of chunk buffers
// (chunk_pipeline.hpp). A chunk is handed to the pipeline when it would outgrow chunk_bytes, when
// its message index is full, and at every flush() (the writer's once-a-second tick): its
// compression thread compresses it, its write thread appends it to the file with one
// MessageIndex record per channel in it, and the writer thread takes it back, without waiting,
// as it adds the next messages or at the next flush, and counts it into the file's chunk index
// and summary. So a killed run loses about the last second, and what is on disk always ends on a
// whole chunk and its indexes: the recovery (mcap_recovery.hpp) cuts back to that point and
// writes the summary. close() hands the last chunk over, waits for every chunk in flight (the
// drain), then writes DataEnd, the summary (schemas, channels, statistics, chunk, attachment and
// metadata indexes), the summary offsets and the footer.
//
// When every chunk buffer is in flight (the compression thread is behind), a message is left
// out at once and counted (messages_not_recorded()), or with wait_for_free_chunk (replays) the
// oldest chunk in flight is waited for; otherwise the writer thread never waits for the
// compression thread except in drain(), close() and abandon().
//
// Past the page cache: each chunk goes to the file in one write with O_DIRECT (the pipeline's
// write thread), framed by the compression thread (its record, its indexes and a Padding record,
// mcap_records.hpp, ending it on a 4096-byte boundary), after opening records padded the same
// way; the tail goes through the page cache. Why: a recording is written once and read rarely, and
// its trip through the page cache was the writer's largest cost at high rates (the kernel's copy,
// on a virtual machine whose fresh pages are dear) and the source of its longest stalls (the dirty
// pages' writeback): docs/performance.md, "Twelfth round". Where the file system has no O_DIRECT
// (tmpfs before Linux 6.6), or takes it at open and refuses the writes, the same bytes go through
// the page cache. What is on the disk is the same either way, and ends on a whole chunk as before.
//
// Every buffer is allocated when the McapFile is made, sized from the options; writing messages,
// chunks and the summary then allocates nothing. A file holds at most max_chunks chunks (the
// summary's index is preallocated): full() says when the recorder must start the next file.
// Failures throw (std::system_error from the file, std::length_error for a message larger than
// the options allow); the file is then left as it was after its last whole chunk.
// Not thread-safe: one thread (the writer) calls everything; the pipeline's threads are internal.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "core/frames/frame.hpp"
#include "core/mcap/mcap_records.hpp"
#include "daemon/io/file_output.hpp"
#include "daemon/mcap/chunk_pipeline.hpp"
#include "daemon/mcap/mcap_file_options.hpp"

namespace pandarcap {

// Channel ids in pandarcap's files.
inline constexpr std::uint16_t kPointsChannel = 1, kHealthChannel = 2, kPacketsChannel = 3;
// The health channel's JSON schema ("pandarcap.Health"), which the live view advertises too.
extern const std::string_view kHealthJsonSchema;

class McapFile {
 public:
  explicit McapFile(const McapFileOptions& options);

  // Creates `path` and writes the header, schemas, channels, metadata and calibration.
  void open(std::string_view path, std::uint64_t create_time_ns);
  bool is_open() const noexcept { return file_.is_open(); }
  // The open file is still where its path says (see OutputFile::at_its_path).
  bool at_its_path() const noexcept { return file_.at_its_path(); }
  bool full() const noexcept {
    return summary_.chunks.size() + pipeline_.in_flight() + 1 >= options_.max_chunks;
  }

  // Each returns false when the message was left out because every chunk buffer is in flight
  // (counted in messages_not_recorded()).
  bool add_frame(const Frame& frame, std::uint64_t log_time);
  bool add_packet(std::span<const std::uint8_t> payload, std::int64_t receive_time_ns,
                  std::uint64_t log_time);
  bool add_health(std::string_view json, std::uint64_t log_time);

  // Hands the open chunk (if any) to the pipeline and counts the chunks that came back written;
  // never waits.
  void flush();
  // Waits for every chunk in flight to be written: the file then ends on all that was flushed.
  void drain();
  // Writes the open chunk, every chunk in flight and the tail, and closes the file.
  void close();
  // After a failure: the file cut back to its last whole chunk and closed, unfinished (a .part
  // for the next start's recovery). Returns the messages that were lost with the open chunk and
  // the chunks in flight (waited for, and discarded).
  std::uint64_t abandon() noexcept;

  // In the chunks written to the open file.
  std::uint64_t messages() const noexcept { return summary_.message_count; }
  std::uint64_t bytes() const noexcept { return file_.is_open() ? file_.size() : 0; }
  // The chunks handed over and not yet written, uncompressed (an upper bound of what they add
  // to bytes(); rotation by size counts them).
  std::uint64_t bytes_in_flight() const noexcept { return bytes_in_flight_; }
  // The records of the open chunk and of the chunks in flight, uncompressed: what abandon()
  // would lose, in bytes.
  std::uint64_t bytes_not_in_file() const noexcept {
    return bytes_in_flight_ + (open_ != nullptr ? open_->records.size() : 0);
  }
  // Left out because every chunk buffer was in flight; for the McapFile's life (monotonic).
  std::uint64_t messages_not_recorded() const noexcept { return not_recorded_; }
  // Chunks written uncompressed because compression was a chunk behind (chunk_pipeline.hpp);
  // for the McapFile's life (monotonic).
  std::uint64_t chunks_uncompressed() const noexcept { return chunks_uncompressed_; }

 private:
  // Room in the open chunk for a message of `data_bytes`: the chunk handed over first when
  // needed; false when no chunk buffer is free.
  bool make_room(std::size_t data_bytes, std::uint16_t channel);
  bool begin_message(std::uint16_t channel, std::uint64_t log_time, std::size_t data_bytes);
  void submit_open();
  // Counts the chunks back from the pipeline, written, into the file's summary (never waits).
  void count_done_chunks();
  // One chunk back: counted, or its failure thrown (std::system_error for a write, the file cut
  // back to its last whole chunk).
  void count_chunk(ChunkBuffer& chunk);
  // `bytes` to the file (the opening records, the tail); on a failure the file is cut back to its
  // last whole chunk and the error thrown (std::system_error).
  void write_out(std::span<const std::uint8_t> bytes);

  McapFileOptions options_;
  std::vector<std::pair<std::string_view, std::string_view>> metadata_;  // into options_
  std::size_t max_message_bytes_;
  std::size_t max_index_entries_;
  OutputFile file_;
  mcap::Summary summary_;
  std::vector<std::uint8_t> out_;  // records on their way to the file
  ChunkPipeline pipeline_;
  ChunkBuffer* open_ = nullptr;           // the chunk messages go to; null when none was free
  std::uint64_t messages_in_flight_ = 0;  // in chunks handed over and not yet written
  std::uint64_t bytes_in_flight_ = 0;     // their records, uncompressed
  std::uint64_t not_recorded_ = 0;
  std::uint64_t chunks_uncompressed_ = 0;
  std::uint32_t sequence_[mcap::kMaxChannels + 1]{};
  std::uint64_t whole_bytes_ = 0;  // the file's length after its last whole chunk
  std::uint64_t file_number_ = 0;  // the files opened: the pipeline's name for the open one
  // False once a file system took O_DIRECT at open but refused its writes (EINVAL): the files
  // after it go through the page cache.
  bool direct_works_ = true;
};

}  // namespace pandarcap
