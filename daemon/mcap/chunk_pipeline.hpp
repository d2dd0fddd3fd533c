// The chunks of an MCAP file on their way to the disk: a fixed pool of chunk buffers, one
// compression thread and one write thread, so the writer thread only appends messages: it never
// compresses a chunk nor waits for one to reach the disk.
//
//   writer thread (McapFile)               compression thread        write thread
//                                          ("pc-mcap-chunks")        ("pc-mcap-write")
//   take_free(): a buffer, filled with
//   messages; its file's descriptor
//   submit(chunk) --- to_compress ------>  CRC-32 of the records,
//                                          compressed into
//                                          chunk.framed between the
//                                          Chunk record's fields and
//                                          its indexes
//                                                --- to_write ----->  chunk.written() appended
//                                                                    to the file in one write
//   take_done() / wait_done()  <------------------- done -----------
//   counts it into the file's chunk index and summary, give_back(chunk)
//
// What the compression thread makes is the chunk as the file holds it: the Chunk record, its
// MessageIndex records and a Padding record that ends it on a 4096-byte boundary, in one
// block-aligned buffer, so it goes to the kernel with O_DIRECT as it is, past the page cache
// (daemon/mcap/mcap_file.hpp says why).
//
// Why a write thread: a write past the page cache lasts as long as the disk takes it (~5 ms for
// a 4 MiB chunk here; a stalled disk, seconds). On the writer thread every chunk's write held the
// frames and the pcap behind it; now a slow MCAP disk holds only MCAP, whose chunks then stay in
// flight until the pool runs out and messages are left out (counted), and the disk sees the
// frames' and the chunks' writes side by side. Compression does not wait for the disk either.
//
// The file's bytes: the writer writes the opening records before it submits the file's first
// chunk and the tail after every chunk is back (close()'s drain), and the write thread writes
// the chunks between, at the descriptor's position, in the order submitted (one thread per
// stage, FIFO queues). So the writer knows each chunk's offset by summing, in the same order, as
// it takes them back: the chunk index and the summary stay the writer's alone. A write that
// fails is reported in the chunk (write_error); the write thread then writes no later chunk of
// that file (each chunk names its file: `file`), and the writer cuts the file back to its last
// whole chunk. A file system that takes O_DIRECT at open but refuses the writes (EINVAL): the
// write thread cuts back to the chunk's start and writes it through the page cache, and says so
// (direct_refused), as McapFile::write_out does for the writer's own records.
//
// A buffer belongs to exactly one side at a time: the writer from take_free() to submit() and
// from take_done() to give_back(), the pipeline's threads in between; the queues' acquire and
// release make each side's writes visible to the next. When every buffer is in flight,
// take_free() returns nullptr at once: the caller leaves the message out and counts it
// (McapFile::messages_not_recorded), as the packet ring drops the newest when full. Only
// close() and abandon() wait (the drain: every chunk handed over comes back), on the done
// queue's futex (SpscQueue::wait_for_data), never a sleep.
//
// Everything is allocated here, at construction: `buffers` chunks of `record_capacity` bytes, a
// framed copy of each (block-aligned: the fields, the codec's bound or the records as they are,
// every index, the padding; its pages are touched only as used), `index_entries` index entries
// per channel, and the compressor. The threads start with every signal blocked (the daemon's
// supervisor takes them with sigwait) and stop in the destructor, after compressing and writing
// whatever was still queued.
#pragma once

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string_view>
#include <thread>
#include <vector>

#include "core/mcap/chunk_codec.hpp"
#include "core/mcap/mcap_records.hpp"
#include "ringbuf/spsc_queue.hpp"

namespace pandarcap {

// Frees what operator new(size, align_val_t{kDirectIoBlock}) gave.
struct AlignedFree {
  void operator()(std::uint8_t* bytes) const noexcept;
};

struct ChunkBuffer {
  // Filled by the writer thread before submit().
  std::vector<std::uint8_t> records;  // the chunk's Message records, uncompressed
  // The file the write thread appends the chunk to (-1: none, the chunk only comes back
  // framed), and which of the writer's files that is (a number of its own per file opened).
  int fd = -1;
  std::uint64_t file = 0;
  std::array<std::vector<mcap::MessageIndexEntry>, mcap::kMaxChannels> index;
  std::uint64_t start_time = 0, end_time = 0, messages = 0;
  // Handed over because it was full, not by a flush or a file's close: only a full chunk
  // waiting behind another says that compression is behind.
  bool full = false;
  // Filled by the compression thread before it hands the chunk back.
  // The chunk as the file holds it: [Chunk record][MessageIndex per channel][Padding], from a
  // 4096-aligned address, left uninitialised (its pages count only once used).
  std::unique_ptr<std::uint8_t[], AlignedFree> framed;
  std::size_t framed_capacity = 0;
  std::size_t record_bytes = 0;   // the Chunk record, its fields and stored records
  std::size_t stored_bytes = 0;   // its records as stored (compressed, or as they are)
  std::size_t index_bytes = 0;    // the MessageIndex records after it
  std::size_t written_bytes = 0;  // all of it with the padding: a multiple of 4096
  // Where each channel's MessageIndex record starts, from the chunk's start; 0 = none.
  std::array<std::uint64_t, mcap::kMaxChannels> index_at{};
  std::uint32_t crc = 0;         // of `records`
  std::string_view compression;  // as the Chunk record names it (a literal: "lz4", "zstd", "")
  // Stored as they are, not compressed: the compression thread was a whole chunk behind
  // (ChunkPipeline's `uncompressed_when_behind`). The chunk's compression is then "", and its
  // CRC is always computed (no codec checks it otherwise).
  bool uncompressed = false;
  bool failed = false;  // the compressor threw (never expected): `error` says why
  std::array<char, 160> error{};
  // Filled by the write thread. The errno of the failed write (0: written, or no file); the
  // chunk's bytes before the failure may be in the file. Also set, to the same errno, for every
  // later chunk of a file whose write failed: none of them is written.
  int write_error = 0;
  // The file system refused its O_DIRECT write (EINVAL): the file was cut back to the chunk's
  // start and the chunk written through the page cache, as is every chunk of the file after it.
  bool direct_refused = false;

  // The chunk's records as the file holds them: compressed, or as they are.
  std::span<const std::uint8_t> stored() const noexcept {
    return {framed.get() + (record_bytes - stored_bytes), stored_bytes};
  }
  // What goes to the file, in one write.
  std::span<const std::uint8_t> written() const noexcept { return {framed.get(), written_bytes}; }
  // Empty again (capacity kept).
  void clear() noexcept;
};

class ChunkPipeline {
 public:
  // `chunk_crc`: each chunk's CRC-32 computed. When false (output.mcap_chunk_crc's default, as
  // rosbag2 writes), every chunk's CRC is 0 ("not computed", as the MCAP spec allows; not a
  // chunk stored as it is, below, which always has its CRC); a zstd
  // frame then carries zstd's checksum instead (XXH64, which the decompressor checks: about
  // 0.17 ms per 4 MiB chunk against the CRC's 0.6 here). lz4 and uncompressed chunks then have
  // no checksum: damage shows only where it breaks the codec or the records (lz4's content
  // checksum, XXH32 in liblz4, measured 2.2 ms per 4 MiB: dearer than the CRC it would replace).
  //
  // `uncompressed_when_behind` (live recording): a chunk the compression thread takes while a
  // full chunk already waits behind it is stored as it is, not compressed. Behind by a whole
  // chunk, the pool is one chunk from full, where the writer would leave messages out
  // (take_free() nullptr): the file grows by what compression would have saved instead, and the
  // thread catches up at once (the stored chunk costs it only its CRC). At one sensor's rate a
  // full chunk never waits behind another (a 4 MiB chunk fills in about 170 ms, lz4 takes
  // about 5); a chunk handed over by a flush or a file's close (rotation, SIGHUP, the end) is
  // not full and does not count. Past what the compressor keeps up with (issue 40's 50 000
  // packets/s on 2 shared cores), some chunks are stored, as many as the CPU leaves. Off for a
  // replay, whose writer waits for a free buffer instead (wait_for_free_chunk) and wants every
  // chunk compressed.
  ChunkPipeline(std::size_t buffers, std::size_t record_capacity, std::size_t index_entries,
                mcap::ChunkCompression compression, int level, bool chunk_crc = true,
                bool uncompressed_when_behind = false);
  ~ChunkPipeline();
  ChunkPipeline(const ChunkPipeline&) = delete;
  ChunkPipeline& operator=(const ChunkPipeline&) = delete;

  std::size_t buffers() const noexcept { return buffers_.size(); }

  // ---- The writer thread only -------------------------------------------------------------
  // An empty buffer, or nullptr when all are in flight (never waits).
  ChunkBuffer* take_free() noexcept;
  // Hands a filled buffer to the compression thread, and then to the write thread (which
  // appends it to chunk->fd, if any).
  void submit(ChunkBuffer* chunk) noexcept;
  // The oldest chunk, compressed and written, or nullptr when none is back yet (never waits).
  ChunkBuffer* take_done() noexcept;
  // The oldest chunk in flight once it is compressed and written (waits for it); nullptr when
  // none is.
  ChunkBuffer* wait_done() noexcept;
  // A chunk from take_done()/wait_done(), written or discarded: free again.
  void give_back(ChunkBuffer* chunk) noexcept;
  // Submitted and not yet taken back.
  std::size_t in_flight() const noexcept { return in_flight_; }
  // Chunks the compression thread has taken up and decided how to store (monotonic; a
  // moment's figure from the writer's side).
  std::size_t taken() const noexcept { return taken_.load(std::memory_order_acquire); }

 private:
  void run() noexcept;         // the compression thread
  void run_writes() noexcept;  // the write thread
  // Appends chunk.written() to chunk.fd (the write thread).
  void write(ChunkBuffer& chunk) noexcept;
  // `behind`: a full chunk waits after this one (stored uncompressed when so configured).
  void compress(ChunkBuffer& chunk, bool behind) noexcept;
  // The Chunk record's fields before the stored records, the indexes and the padding after.
  void frame(ChunkBuffer& chunk) noexcept;

  mcap::ChunkCompression compression_;
  bool chunk_crc_;
  bool uncompressed_when_behind_;
  std::unique_ptr<mcap::ChunkCompressor> compressor_;  // null without compression
  std::vector<std::unique_ptr<ChunkBuffer>> buffers_;
  std::vector<ChunkBuffer*> free_;  // the writer's; capacity for every buffer
  std::size_t in_flight_ = 0;
  // nullptr in to_compress_ tells the compression thread to stop, which passes it on in
  // to_write_ to the write thread.
  ringbuf::SpscQueue<ChunkBuffer*> to_compress_, to_write_, done_;
  std::atomic<std::size_t> taken_{0};
  std::vector<std::uint8_t> fields_;  // the compression thread's: a chunk's fields and indexes
  // The write thread's: the last file whose write failed (0: none), and its errno.
  std::uint64_t failed_file_ = 0;
  int failed_error_ = 0;
  std::thread thread_, write_thread_;
};

}  // namespace pandarcap
