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
// A rotation must not wait for the disk: close_later() hands the last chunk over and returns at
// once, and the next file opens while that one's chunks are still in flight. Two files are then
// written at once, each with its own descriptor, summary and chunk index (a Slot): the chunks
// come back in the order submitted, so the closing file's are all back before the first of the
// next file's, and as the last one is counted its tail is written (through the page cache, after
// the disk took its chunks). take_closed() then gives its outcome. Only one file closes at a
// time: close_later() again while one still closes waits for it (finish_closing()), so a
// stalled disk holds the writer only at a second rotation inside the stall (issue 40's hostile
// finding: a 2 s stall plus a SIGHUP held the writer, and dropped frames, for its whole length).
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

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
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

// How a file that closed while the next one was written ended (McapFile::take_closed).
struct McapClosedFile {
  std::uint64_t messages = 0;  // in its whole chunks, on the disk
  // Its tail written: a file every reader accepts. After a failure too, when the file could be
  // cut back to its last whole chunk and the tail written there; otherwise it is left for the
  // next start's recovery (mcap_recovery.hpp).
  bool finished = false;
  // The first write that failed (a chunk, the tail, the close), if any; `error.path` stays valid
  // until the next open().
  io::IoError error;
  // What its failure lost: the messages of its chunks not written, and their records'
  // uncompressed bytes.
  std::uint64_t messages_lost = 0, bytes_lost = 0;
};

class McapFile {
 public:
  explicit McapFile(const McapFileOptions& options);

  // Creates `path` and writes the header, schemas, channels, metadata and calibration.
  void open(std::string_view path, std::uint64_t create_time_ns);
  bool is_open() const noexcept { return now_->file.is_open(); }
  // The open file is still where its path says (see OutputFile::at_its_path).
  bool at_its_path() const noexcept { return now_->file.at_its_path(); }
  bool full() const noexcept {
    return now_->summary.chunks.size() + now_->chunks_in_flight + 1 >= options_.max_chunks;
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
  // Hands the open chunk over and lets the file finish without waiting: is_open() is then false
  // and open() may start the next file while this one's chunks are in flight; its tail is
  // written once the last is back, as the writer counts chunks (flush(), the next messages,
  // drain()). A failure of the file being left throws first (as flush() does), and leaves it
  // open for abandon(). At most one file closes at a time: the caller takes the one before with
  // take_closed() first.
  void close_later();
  // A file is closing, or closed and not yet taken.
  bool closing() const noexcept { return closing_ != nullptr; }
  // Waits for the closing file's chunks and writes its tail (never throws: its failure is its
  // outcome). Then take_closed() gives it.
  void finish_closing() noexcept;
  // The closing file's outcome, once its last chunk is back and its tail written (or its
  // failure met): true, with `closed` filled, and the slot free for a later close_later().
  bool take_closed(McapClosedFile& closed) noexcept;
  // After a failure: the file cut back to its last whole chunk and closed, unfinished (a .part
  // for the next start's recovery), or, given `finished`, with its tail written there from the
  // summary of its whole chunks when the disk takes it (*finished says which): what the recovery
  // would write, without reading the file back on the writer thread. Returns the messages that
  // were lost with the open chunk and the chunks in flight: this file's are waited for and
  // discarded, a closing file's are not (they are counted into it as they come back, so a
  // failure of the next file while a stalled disk holds the one before does not wait for it).
  std::uint64_t abandon(bool* finished = nullptr) noexcept;
  // The open file is gone (removed): abandon()'s count, without waiting. Its chunks in flight
  // may queue behind a closing file's held by a stalled disk; its descriptor is kept aside
  // until they are back (then cut back to its last whole chunk and closed), and open() may
  // start the next file meanwhile, which may be let go in turn.
  std::uint64_t let_go() noexcept;
  // A file let go still has chunks in flight (drain() waits for them).
  bool leaving() const noexcept { return leaving_count_ != 0; }

  // In the chunks written to the open file.
  std::uint64_t messages() const noexcept { return now_->summary.message_count; }
  std::uint64_t bytes() const noexcept { return now_->file.is_open() ? now_->file.size() : 0; }
  // The same, for the closing file until it is taken (0 when none).
  std::uint64_t closing_messages() const noexcept {
    return closing_ != nullptr ? closing_->summary.message_count : 0;
  }
  std::uint64_t closing_bytes() const noexcept {
    return closing_ != nullptr ? closing_->file.size() : 0;
  }
  // The chunks handed over and not yet written, uncompressed (an upper bound of what they add
  // to bytes(); rotation by size counts them).
  std::uint64_t bytes_in_flight() const noexcept { return now_->bytes_in_flight; }
  // The records of the open chunk and of the chunks in flight, uncompressed: what abandon()
  // would lose, in bytes.
  std::uint64_t bytes_not_in_file() const noexcept {
    return now_->bytes_in_flight + (open_ != nullptr ? open_->records.size() : 0);
  }
  // Left out because every chunk buffer was in flight; for the McapFile's life (monotonic).
  std::uint64_t messages_not_recorded() const noexcept { return not_recorded_; }
  // Chunks written uncompressed because compression was a chunk behind (chunk_pipeline.hpp);
  // for the McapFile's life (monotonic).
  std::uint64_t chunks_uncompressed() const noexcept { return chunks_uncompressed_; }

 private:
  // Room in the open chunk for a message of `data_bytes`: the chunk handed over first when
  // needed; false when no chunk buffer is free.
  // One file's own state: the one messages go to (now_), or the one closing (closing_).
  struct Slot {
    OutputFile file;
    mcap::Summary summary;
    std::uint64_t number = 0;              // the pipeline's name for it (ChunkBuffer::file)
    std::uint64_t whole_bytes = 0;         // its length after its last whole chunk
    std::uint64_t messages_in_flight = 0;  // in chunks handed over and not yet counted written
    std::uint64_t bytes_in_flight = 0;     // their records, uncompressed
    std::size_t chunks_in_flight = 0;      // handed over and not yet back
  };

  bool make_room(std::size_t data_bytes, std::uint16_t channel);
  bool begin_message(std::uint16_t channel, std::uint64_t log_time, std::size_t data_bytes);
  void submit_open();
  // Counts the chunks back from the pipeline, written, into their file's summary (never waits).
  void count_done_chunks();
  // One chunk back, into the file it belongs to: the open file's failure thrown, the closing
  // file's kept in its outcome.
  void take_back(ChunkBuffer& chunk);
  // One chunk of the closing file back: counted, or its failure kept; the file settled when it
  // was the last.
  void take_closing(ChunkBuffer& chunk) noexcept;
  // A file let go (let_go) while its chunks were in flight: its descriptor, kept until the
  // last is back, and where to cut it back to then.
  struct Leaving {
    OutputFile file;
    std::uint64_t number = 0;
    std::uint64_t whole_bytes = 0;
    std::size_t chunks_in_flight = 0;  // 0: the entry is free
  };
  // The file let go that `chunk` belongs to, if any.
  Leaving* leaving_of(const ChunkBuffer& chunk) noexcept;
  // One chunk of a file let go back: its buffer free; the file closed when it was the last.
  void take_leaving(Leaving& leaving, ChunkBuffer& chunk) noexcept;
  // One chunk of the open file back: counted, or its failure thrown (std::system_error for a
  // write, the file cut back to its last whole chunk).
  void count_chunk(ChunkBuffer& chunk);
  // One chunk back into `slot`'s summary; its buffer free again either way. The failure is
  // returned (the file cut back to its last whole chunk): the chunk's messages then stay in
  // slot.messages_in_flight, lost.
  io::IoError count_into(Slot& slot, ChunkBuffer& chunk) noexcept;
  // The closing file, once its last chunk is back: its tail written, or, after a failure, cut
  // back; closed; its outcome ready.
  void settle_closing() noexcept;
  // `bytes` to `slot`'s file (the opening records, the tail); on a failure the file is cut back
  // to its last whole chunk and the failure returned.
  io::IoError write_out(Slot& slot, std::span<const std::uint8_t> bytes) noexcept;
  // The file's tail (DataEnd, the summary, the footer) into out_.
  void make_tail(const Slot& slot);
  // `slot`'s tail written after its last whole chunk, from its summary (with `cut`, after a
  // failure, the file cut back there first); the failure returned.
  io::IoError finish_whole(Slot& slot, bool cut) noexcept;

  McapFileOptions options_;
  std::vector<std::pair<std::string_view, std::string_view>> metadata_;  // into options_
  std::size_t max_message_bytes_;
  std::size_t max_index_entries_;
  std::array<Slot, 2> slots_;
  Slot* now_ = &slots_[0];
  Slot* closing_ = nullptr;  // closing, or closed and not yet taken
  // One entry per chunk buffer: a file let go holds one in flight at least, so there is always
  // room for the next (made at start: letting go allocates nothing).
  std::vector<Leaving> leaving_;
  std::size_t leaving_count_ = 0;  // entries in use
  McapClosedFile closed_;          // closing_'s outcome so far
  bool closed_ready_ = false;
  std::vector<std::uint8_t> out_;  // records on their way to the file
  // The opening records copied to block-aligned memory, for their O_DIRECT write (a rotation's
  // next file opens while every chunk buffer may be in flight).
  std::unique_ptr<std::uint8_t[], AlignedFree> opening_;
  std::size_t opening_capacity_ = 0;
  ChunkPipeline pipeline_;
  ChunkBuffer* open_ = nullptr;  // the chunk messages go to; null when none was free
  std::uint64_t not_recorded_ = 0;
  std::uint64_t chunks_uncompressed_ = 0;
  std::uint32_t sequence_[mcap::kMaxChannels + 1]{};
  std::uint64_t file_number_ = 0;  // the files opened: the pipeline's name for the open one
  // False once a file system took O_DIRECT at open but refused its writes (EINVAL): the files
  // after it go through the page cache.
  bool direct_works_ = true;
};

}  // namespace pandarcap
