#include "daemon/mcap/chunk_pipeline.hpp"

#include <pthread.h>
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <exception>
#include <new>
#include <stdexcept>
#include <system_error>

#include "daemon/io/file_output.hpp"

namespace pandarcap {
namespace {

// Idle, the thread wakes this often to look again (a notify is never missed; this only bounds
// the cost of a bug to a delay).
constexpr auto kChunkIdleWait = std::chrono::seconds(1);

// The longest Chunk record fields: those of a "zstd" chunk (lz4's and stored chunks' are shorter).
constexpr std::size_t kChunkFieldsMax = mcap::chunk_header_bytes("zstd");

}  // namespace

void AlignedFree::operator()(std::uint8_t* bytes) const noexcept {
  ::operator delete (bytes, std::align_val_t{kDirectIoBlock});
}

void ChunkBuffer::clear() noexcept {
  records.clear();
  for (auto& entries : index)
    entries.clear();
  start_time = end_time = messages = 0;
  full = false;
  record_bytes = stored_bytes = index_bytes = written_bytes = 0;
  index_at.fill(0);
  crc = 0;
  compression = {};
  uncompressed = false;
  failed = false;
  error[0] = '\0';
  fd = -1;
  file = 0;
  write_error = 0;
  direct_refused = false;
}

ChunkPipeline::ChunkPipeline(std::size_t buffers, std::size_t record_capacity,
                             std::size_t index_entries, mcap::ChunkCompression compression,
                             int level, bool chunk_crc, bool uncompressed_when_behind)
    : compression_(compression),
      chunk_crc_(chunk_crc),
      uncompressed_when_behind_(uncompressed_when_behind),
      // Room for every buffer and the stop marker.
      to_compress_(std::bit_ceil(buffers + 1)),
      to_write_(std::bit_ceil(buffers + 1)),
      done_(std::bit_ceil(buffers + 1)) {
  if (buffers == 0) throw std::invalid_argument("an MCAP chunk pipeline needs a buffer");
  if (compression != mcap::ChunkCompression::kNone) {
    // Without the chunk's CRC, zstd's frame checksum finds damage (XXH64: a third of CRC-32's
    // cost). lz4's content checksum (XXH32) would cost 3.7 times the CRC: not asked for.
    compressor_ =
        std::make_unique<mcap::ChunkCompressor>(compression, record_capacity, level, !chunk_crc_);
  }
  // Every channel's MessageIndex record, full.
  const std::size_t index_bytes =
      mcap::kMaxChannels * (mcap::kRecordPrefixBytes + 2 + 4 + index_entries * 16);
  fields_.reserve(kChunkFieldsMax + index_bytes);
  // The fields, the stored records (compressed: the codec's bound; as they are: the records),
  // the indexes, and the padding's at most a block and its prefix.
  const std::size_t stored_max = std::max(record_capacity, compressor_ ? compressor_->bound() : 0);
  const std::size_t framed_capacity = whole_direct_blocks(
      kChunkFieldsMax + stored_max + index_bytes + kDirectIoBlock + mcap::kRecordPrefixBytes);
  buffers_.reserve(buffers);
  free_.reserve(buffers);
  for (std::size_t i = 0; i < buffers; ++i) {
    auto chunk = std::make_unique<ChunkBuffer>();
    chunk->records.reserve(record_capacity);
    chunk->framed.reset(static_cast<std::uint8_t*>(
        ::operator new (framed_capacity, std::align_val_t{kDirectIoBlock})));
    chunk->framed_capacity = framed_capacity;
    for (auto& entries : chunk->index)
      entries.reserve(index_entries);
    free_.push_back(chunk.get());
    buffers_.push_back(std::move(chunk));
  }
  // Every signal blocked while the threads are made, so they start with them all blocked. The
  // write thread first: were the compression thread not made, the stop marker ends it.
  sigset_t all, before;
  sigfillset(&all);
  pthread_sigmask(SIG_SETMASK, &all, &before);
  try {
    write_thread_ = std::thread([this] {
      pthread_setname_np(pthread_self(), "pc-mcap-write");
      run_writes();
    });
    try {
      thread_ = std::thread([this] {
        pthread_setname_np(pthread_self(), "pc-mcap-chunks");
        run();
      });
    } catch (...) {
      to_write_.try_push(nullptr);
      to_write_.notify();
      write_thread_.join();
      throw;
    }
  } catch (...) {
    pthread_sigmask(SIG_SETMASK, &before, nullptr);
    throw;
  }
  pthread_sigmask(SIG_SETMASK, &before, nullptr);
}

ChunkPipeline::~ChunkPipeline() {
  to_compress_.try_push(nullptr);  // never full: it has room for every buffer and the marker
  to_compress_.notify();
  thread_.join();  // which passes the marker on to the write thread
  write_thread_.join();
}

ChunkBuffer* ChunkPipeline::take_free() noexcept {
  if (free_.empty()) return nullptr;
  ChunkBuffer* chunk = free_.back();
  free_.pop_back();
  return chunk;
}

void ChunkPipeline::submit(ChunkBuffer* chunk) noexcept {
  to_compress_.try_push(chunk);  // never full: at most every buffer is queued
  ++in_flight_;
  to_compress_.notify();
}

ChunkBuffer* ChunkPipeline::take_done() noexcept {
  ChunkBuffer* chunk = nullptr;
  if (in_flight_ == 0 || !done_.try_pop(chunk)) return nullptr;
  --in_flight_;
  return chunk;
}

ChunkBuffer* ChunkPipeline::wait_done() noexcept {
  if (in_flight_ == 0) return nullptr;
  ChunkBuffer* chunk = nullptr;
  while (!done_.try_pop(chunk))
    done_.wait_for_data(kChunkIdleWait);
  --in_flight_;
  return chunk;
}

void ChunkPipeline::give_back(ChunkBuffer* chunk) noexcept {
  chunk->clear();
  free_.push_back(chunk);  // within the reserved capacity: one slot per buffer
}

void ChunkPipeline::run() noexcept {
  while (true) {
    ChunkBuffer* chunk = nullptr;
    if (!to_compress_.try_pop(chunk)) {
      to_compress_.wait_for_data(kChunkIdleWait);
      continue;
    }
    if (chunk == nullptr) {  // the destructor's stop marker: the write thread's too
      to_write_.try_push(nullptr);
      to_write_.notify();
      return;
    }
    // A full chunk already queued behind this one (not the stop marker, nor a chunk a flush or
    // a close handed over): a chunk behind.
    ChunkBuffer* const* next = to_compress_.front();
    const bool behind = next != nullptr && *next != nullptr && (*next)->full;
    taken_.fetch_add(1, std::memory_order_release);
    compress(*chunk, behind);
    to_write_.try_push(chunk);  // never full: room for every buffer and the marker
    to_write_.notify();
  }
}

void ChunkPipeline::run_writes() noexcept {
  while (true) {
    ChunkBuffer* chunk = nullptr;
    if (!to_write_.try_pop(chunk)) {
      to_write_.wait_for_data(kChunkIdleWait);
      continue;
    }
    if (chunk == nullptr) return;  // the stop marker, after every chunk before it
    write(*chunk);
    done_.try_push(chunk);  // never full: room for every buffer
    done_.notify();
  }
}

void ChunkPipeline::write(ChunkBuffer& chunk) noexcept {
  if (chunk.fd < 0 || chunk.failed) return;  // a failed chunk: the writer abandons the file
  if (chunk.file == failed_file_) {
    chunk.write_error = failed_error_;  // after a failed write, nothing more of that file
    return;
  }
  // Where the chunk starts: the end of the chunk before it, or of the opening records.
  const off_t start = ::lseek(chunk.fd, 0, SEEK_CUR);
  std::uint64_t written = 0;
  int error = write_fully(chunk.fd, chunk.written(), written);
  if (error == EINVAL && start >= 0 && direct_io_on(chunk.fd)) {
    // Took O_DIRECT at open, refuses the writes: the page cache, from the chunk's start.
    if (end_direct_io(chunk.fd) && cut_back(chunk.fd, static_cast<std::uint64_t>(start))) {
      chunk.direct_refused = true;
      error = write_fully(chunk.fd, chunk.written(), written);
    }
  }
  if (error != 0) {
    chunk.write_error = error;
    failed_file_ = chunk.file;
    failed_error_ = error;
  }
}

void ChunkPipeline::compress(ChunkBuffer& chunk, bool behind) noexcept {
  chunk.uncompressed = compressor_ && behind && uncompressed_when_behind_;
  // Stored as it is when behind: no codec's checksum would find damage in it, so its CRC always
  // (0.6 ms per 4 MiB, against lz4's 4.4 for the compression it saves).
  chunk.crc =
      chunk_crc_ || chunk.uncompressed ? mcap::crc32(chunk.records) : 0;  // 0: "not computed"
  chunk.compression = mcap::compression_name(
      compressor_ && !chunk.uncompressed ? compression_ : mcap::ChunkCompression::kNone);
  std::uint8_t* const stored = chunk.framed.get() + mcap::chunk_header_bytes(chunk.compression);
  if (!compressor_ || chunk.uncompressed) {
    if (!chunk.records.empty()) std::memcpy(stored, chunk.records.data(), chunk.records.size());
    chunk.stored_bytes = chunk.records.size();
  } else {
    try {
      chunk.stored_bytes =
          compressor_->compress(chunk.records, std::span(stored, compressor_->bound()));
    } catch (const std::exception& error) {
      chunk.failed = true;
      const std::size_t n = std::min(std::strlen(error.what()), chunk.error.size() - 1);
      std::memcpy(chunk.error.data(), error.what(), n);
      chunk.error[n] = '\0';
      return;
    }
  }
  frame(chunk);
}

void ChunkPipeline::frame(ChunkBuffer& chunk) noexcept {
  // Within fields_'s reserved capacity and the framed buffer's (sized for the longest fields,
  // the codec's bound and every index full): nothing allocates, nothing overflows.
  fields_.clear();
  mcap::ByteWriter w(fields_);
  mcap::write_chunk_header(w, chunk.start_time, chunk.end_time, chunk.records.size(), chunk.crc,
                           chunk.compression, chunk.stored_bytes);
  std::memcpy(chunk.framed.get(), fields_.data(), fields_.size());
  chunk.record_bytes = fields_.size() + chunk.stored_bytes;
  fields_.clear();
  for (std::size_t c = 0; c < mcap::kMaxChannels; ++c) {
    if (chunk.index[c].empty()) continue;
    chunk.index_at[c] = chunk.record_bytes + w.size();
    mcap::write_message_index(w, static_cast<std::uint16_t>(c + 1), chunk.index[c]);
  }
  chunk.index_bytes = fields_.size();
  std::uint8_t* const end = chunk.framed.get() + chunk.record_bytes;
  if (!fields_.empty()) std::memcpy(end, fields_.data(), fields_.size());
  const std::size_t used = chunk.record_bytes + chunk.index_bytes;
  const std::size_t padding = mcap::padding_bytes(used, kDirectIoBlock);
  mcap::write_padding(std::span(chunk.framed.get() + used, padding));
  chunk.written_bytes = used + padding;
}

}  // namespace pandarcap
