// Reads the Pandar packets out of an MCAP file: the messages of its pandar_msgs/msg/PandarPacket
// channel (what pandarcapd writes with output.mcap_packets = true, or Hesai's ROS 2 driver
// records), in file order, each as a CaptureRecord whose payload is the packet and whose time is
// the message's log time. CaptureReader uses it for a file that starts with the MCAP magic, so
// the replay and pandarcap-inspect read MCAP as they read pcap.
//
// Streaming, bounded memory: records are read one at a time from the data section (never the
// whole file, never the summary); a chunk is held whole, compressed and decompressed, and a chunk
// claiming more than kMaxChunkBytes is refused. Chunks compressed with zstd, lz4 (the LZ4
// frame format) or not at all are read (any other compression: a clear error). Schemas and channels
// may come anywhere before their messages, inside chunks or not.
//
// Which packets: messages on a channel with message encoding "cdr" whose schema is named
// pandar_msgs/msg/PandarPacket; when a file holds several such channels (several sensors), the
// first one with a message is read and the others' messages are counted as port_filtered. Other
// channels' messages (points, health) are not records.
//
// What the packets do not carry: their addresses. Source and destination are left empty
// (0.0.0.0:0), so a port or sensor-address filter cannot apply; pandarcapd recorded only the
// sensor's datagrams to its data port in the first place.
//
// Damage, and the chunk index: a finished file ends with a summary whose ChunkIndex records say
// where every chunk starts (read at open: the footer, then the summary, its CRC checked). With it,
// a chunk that does not parse, decompress or pass its CRC, or a record inside it that does not
// parse, is skipped, counted (stats.chunks_skipped, and the packets its message index lists in
// stats.packets_skipped) and named (first_damage()), and reading goes on at the next chunk the
// index lists. A chunk whose length differs from its index's is read with the index's (counted
// in stats.records_damaged); another record's length that runs over an indexed chunk's start is
// caught there, and reading resumes at that chunk; one that runs past the data section (the
// summary's start) or the end of a file that has its footer is damage too, never "cut off" (a
// file cut while recording has no footer).
//
// End of input: kEnd at the DataEnd record (or the footer); kTruncated when the file ends before
// it and has no footer (a file copied while being written, or one a killed run left and no start
// finished); kError for damage with no later chunk to go on at (or no chunk index).
#pragma once

#include <bitset>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "core/sensors/sensor_model_id.hpp"
#include "daemon/pcap/capture_reader.hpp"

namespace pandarcap {

// A chunk's uncompressed records: twice the largest output.mcap_chunk_bytes (256 MiB; a chunk
// exceeds it by at most one message). A claim beyond it is damage, refused before allocation.
inline constexpr std::uint64_t kMaxChunkBytes = 512ull << 20;
// Any other record read whole (a Message, Schema or Channel outside chunks, a chunk as stored).
inline constexpr std::uint64_t kMaxMcapRecordBytes = 512ull << 20;

class McapPacketReader {
 public:
  // Reads the file `fd` (a regular file; owned from here, closed by the destructor) whose first
  // bytes are the MCAP magic. `path` names it in errors.
  McapPacketReader(int fd, std::string path);
  ~McapPacketReader();
  McapPacketReader(const McapPacketReader&) = delete;
  McapPacketReader& operator=(const McapPacketReader&) = delete;

  // The next packet, counted in `stats` (records: packet messages read; udp_datagrams: yielded;
  // malformed: messages that are not a whole PandarPacket). kRecord fills `out` (its payload valid
  // until the next call); anything else is final, with error() saying why.
  CaptureStatus next(CaptureRecord& out, CaptureStats& stats);
  const std::string& error() const noexcept { return error_; }
  std::uint64_t offset() const noexcept { return offset_; }  // of the next top-level record
  // The first damage skipped over ("" while none), with the file's name.
  const std::string& first_damage() const noexcept { return first_damage_; }
  // The sensor model the packets channel's metadata names (sensor_model: pandarcapd's files),
  // once its Channel record has been read: the channel being read, else the first that names
  // one. A hint for a reader whose packets name none; the packets are authoritative.
  std::optional<SensorModelId> named_model() const noexcept;

 private:
  enum class Handled { kNone, kRecord, kFailed };
  CaptureStatus fail(CaptureStatus status, const std::string& what);
  bool read_at(std::uint64_t offset, std::uint8_t* out, std::size_t n);
  // One record of the data section (top level or inside a chunk).
  Handled handle(std::uint8_t op, std::span<const std::uint8_t> content, std::uint64_t offset,
                 CaptureRecord& out, CaptureStats& stats);
  Handled load_chunk(std::span<const std::uint8_t> content, std::uint64_t offset);
  // The footer's summary, for the chunk index (nothing when the file has none or it is damaged).
  void read_chunk_index();
  // Damage at `offset`: goes on at the first indexed chunk after it (true), counting the chunk
  // skipped when `chunk` and naming the first damage; false when there is none to go on at.
  bool skip_past(std::uint64_t offset, bool chunk, const std::string& what, CaptureStats& stats);
  // The packets the message index after the indexed chunk `i` lists (0 when it is unreadable).
  std::uint64_t indexed_packets(std::size_t i);

  struct IndexedChunk {
    std::uint64_t start = 0, length = 0, message_index_length = 0;
  };

  int fd_;
  std::string path_;
  std::uint64_t size_ = 0;
  std::uint64_t offset_;                   // of the next top-level record
  std::vector<std::uint8_t> record_;       // the top-level record being read
  std::unique_ptr<std::uint8_t[]> chunk_;  // the current chunk's records, uncompressed
  std::uint64_t chunk_capacity_ = 0, chunk_size_ = 0, chunk_pos_ = 0;
  std::uint64_t chunk_offset_ = 0;  // its Chunk record's offset in the file
  bool in_chunk_ = false;
  std::bitset<65536> packet_schemas_, packet_channels_;
  std::optional<std::uint16_t> channel_;  // the packet channel being read
  static constexpr std::size_t kMaxNamedChannels = 64;
  std::vector<std::pair<std::uint16_t, SensorModelId>> named_models_;  // channel, sensor_model
  std::string error_;
  std::string first_damage_;
  bool has_footer_ = false;           // the file ends with a footer and the closing magic
  std::vector<IndexedChunk> chunks_;  // by start offset; empty: no usable chunk index
  std::size_t next_chunk_ = 0;        // the first indexed chunk not yet reached
  std::uint64_t data_end_ = 0;        // where the summary starts (a trusted footer's); 0: unknown
};

}  // namespace pandarcap
