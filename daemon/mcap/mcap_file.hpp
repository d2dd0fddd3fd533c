// One MCAP file being written (https://mcap.dev/spec; the records are core/mcap/).
//
// Messages collect in an uncompressed chunk in memory; a chunk is compressed and written, with
// one MessageIndex record per channel in it, when it would outgrow chunk_bytes, when its message
// index is full, and at every flush() (the writer's once-a-second tick), so a killed run loses at
// most the last second, and what is on disk always ends on a whole chunk and its indexes: the
// recovery (mcap_recovery.hpp) cuts back to that point and writes the summary. close() writes the
// last chunk, DataEnd, the summary (schemas, channels, statistics, chunk, attachment and metadata
// indexes), the summary offsets and the footer.
//
// Every buffer is allocated when the McapFile is made, sized from the options; writing messages,
// chunks and the summary then allocates nothing. A file holds at most max_chunks chunks (the
// summary's index is preallocated): full() says when the recorder must start the next file.
// Failures throw (std::system_error from the file, std::length_error for a message larger than
// the options allow); the file is then left as it was after its last whole chunk.
#pragma once

#include <cstddef>
#include <cstdint>
#include <initializer_list>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "core/frame.hpp"
#include "core/mcap/chunk_codec.hpp"
#include "core/mcap/mcap_records.hpp"
#include "daemon/io/file_output.hpp"
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
  bool full() const noexcept { return summary_.chunks.size() + 1 >= options_.max_chunks; }

  void add_frame(const Frame& frame, std::uint64_t log_time);
  void add_packet(std::span<const std::uint8_t> payload, std::int64_t receive_time_ns,
                  std::uint64_t log_time);
  void add_health(std::string_view json, std::uint64_t log_time);

  // Writes the open chunk (if any).
  void flush();
  // Writes the open chunk and the tail, and closes the file.
  void close();
  // After a failure: the file cut back to its last whole chunk and closed, unfinished (a .part
  // for the next start's recovery). Returns the messages that were lost with the open chunk.
  std::uint64_t abandon() noexcept;

  std::uint64_t messages() const noexcept { return summary_.message_count; }
  std::uint64_t bytes() const noexcept { return file_.is_open() ? file_.size() : 0; }

 private:
  // Room in the chunk for a message of `data_bytes`: writes the chunk first when needed.
  void make_room(std::size_t data_bytes, std::uint16_t channel);
  void begin_message(std::uint16_t channel, std::uint64_t log_time, std::size_t data_bytes);
  void write_chunk();
  // `parts` to the file, one after the other; on a failure the file is cut back to its last
  // whole chunk and the error rethrown.
  void write_out(std::initializer_list<std::span<const std::uint8_t>> parts);

  McapFileOptions options_;
  std::vector<std::pair<std::string_view, std::string_view>> metadata_;  // into options_
  std::size_t max_message_bytes_;  // before compressor_, which is sized from it
  mcap::ChunkCompressor compressor_;
  std::size_t max_index_entries_;
  OutputFile file_;
  mcap::Summary summary_;
  std::vector<std::uint8_t> chunk_;       // the open chunk's Message records, uncompressed
  std::vector<std::uint8_t> compressed_;  // its compressed form
  std::vector<std::uint8_t> out_;         // records on their way to the file
  std::vector<mcap::MessageIndexEntry> index_[mcap::kMaxChannels];
  std::uint64_t chunk_start_time_ = 0, chunk_end_time_ = 0;
  std::uint64_t chunk_messages_ = 0;
  std::uint32_t sequence_[mcap::kMaxChannels + 1]{};
  std::uint64_t whole_bytes_ = 0;  // the file's length after its last whole chunk
};

}  // namespace pandarcap
