#include "daemon/mcap/mcap_file.hpp"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <stdexcept>
#include <utility>

#include "core/frames/pcd.hpp"
#include "core/mcap/ros2_messages.hpp"

namespace pandarcap {
namespace {

// The health record's shape for readers that show a schema (Foxglove): an object with the
// state, its reason and the counters; the record itself documents every key
// (docs/daemon.md).
constexpr std::string_view kHealthSchema =
    R"({"type":"object","title":"pandarcap health record","properties":{)"
    R"("state":{"type":"string","enum":["starting","ok","no_data","degraded","error"]},)"
    R"("reason":{"type":"string"},"counters":{"type":"object"},"gauges":{"type":"object"}},)"
    R"("required":["state","counters"]})";

// Generous room for the records around a chunk, its indexes and a file's tail per chunk.
constexpr std::size_t kRecordSlack = 64 * 1024;
constexpr std::size_t kTailBytesPerChunk = 160;
// Room for a file's path (PATH_MAX).
constexpr std::size_t kPathReserve = 4096;

}  // namespace

const std::string_view kHealthJsonSchema = kHealthSchema;

McapFile::McapFile(const McapFileOptions& options)
    : options_(options),
      max_message_bytes_(
          mcap::pointcloud2_prefix_bytes(options.frame_id.size(), options.format.layout) +
          options.max_frame_points * pcd_point_bytes(options.format.layout) + 1),
      // A chunk holds chunk_bytes; its smallest messages (packets) are over 1 KB.
      max_index_entries_(options.chunk_bytes / 1024 + 64),
      leaving_(std::max<std::size_t>(options.chunk_buffers, 1)),
      pipeline_(std::max<std::size_t>(options.chunk_buffers, 1),
                options.chunk_bytes + mcap::kMessagePrefixBytes + max_message_bytes_,
                max_index_entries_, options.compression, options.compression_level,
                options.chunk_crc, !options.wait_for_free_chunk) {
  // out_ holds the opening records (the calibration among them) and their padding, or the tail
  // (the chunks go to the file framed by the compression thread).
  std::size_t metadata_bytes = options.device_name.size();
  for (const auto& [key, value] : options.metadata)
    metadata_bytes += key.size() + value.size();
  const std::size_t opening_bytes =
      kRecordSlack + options.calibration_csv.size() + metadata_bytes + kDirectIoBlock;
  out_.reserve(opening_bytes + options.max_chunks * kTailBytesPerChunk);
  opening_capacity_ = whole_direct_blocks(opening_bytes);
  opening_.reset(static_cast<std::uint8_t*>(
      ::operator new (opening_capacity_, std::align_val_t{kDirectIoBlock})));
  // What open() records, made here so that starting a file (a rotation) allocates nothing.
  for (const auto& [key, value] : options_.metadata)
    metadata_.emplace_back(key, value);
  mcap::Summary& summary = slots_[0].summary;
  summary.schemas.push_back(
      {1, std::string(mcap::kPointCloud2Name), "ros2msg", std::string(mcap::kPointCloud2Schema)});
  summary.schemas.push_back({2, "pandarcap.Health", "jsonschema", std::string(kHealthSchema)});
  summary.channels.push_back({kPointsChannel, 1, options.points_topic, "cdr", {}});
  summary.channels.push_back({kHealthChannel, 2, options.health_topic, "json", {}});
  if (options.packets) {
    summary.schemas.push_back({3, std::string(mcap::kPandarPacketName), "ros2msg",
                               std::string(mcap::kPandarPacketSchema)});
    mcap::ChannelInfo packets{kPacketsChannel, 3, options.packets_topic, "cdr", {}};
    if (!options.sensor_model.empty())
      packets.metadata.emplace_back("sensor_model", options.sensor_model);
    summary.channels.push_back(std::move(packets));
  }
  slots_[1].summary.schemas = summary.schemas;
  slots_[1].summary.channels = summary.channels;
  for (Slot& slot : slots_) {
    // Either slot opens the next file (a rotation alternates them): neither allocates then.
    slot.file.reserve_path(kPathReserve);
    slot.summary.metadata.reserve(2);  // "pandarcap", "foxglove"
    slot.summary.attachments.reserve(1);
    slot.summary.chunks.reserve(options.max_chunks);
  }
  for (Leaving& leaving : leaving_)
    leaving.file.reserve_path(kPathReserve);  // a slot's file and this one trade places
}

void McapFile::open(std::string_view path, std::uint64_t create_time_ns) {
  Slot& slot = *now_;
  slot.file.open(path, direct_works_ ? OutputFile::Mode::kCreateDirect : OutputFile::Mode::kCreate);
  slot.number = ++file_number_;
  mcap::Summary& summary = slot.summary;
  summary.chunks.clear();
  summary.attachments.clear();
  summary.metadata.clear();
  summary.message_count = 0;
  summary.channel_message_count.fill(0);
  summary.message_start_time = summary.message_end_time = 0;
  // close(), close_later() and abandon() handed over or dropped the open chunk, and this slot's
  // chunks all came back before it was taken (take_closed) or left (abandon).
  if (open_ != nullptr) open_->clear();
  slot.messages_in_flight = 0;
  slot.bytes_in_flight = 0;
  slot.chunks_in_flight = 0;
  for (auto& s : sequence_)
    s = 0;
  out_.clear();
  mcap::ByteWriter w(out_);
  w.bytes(mcap::kMagic);
  mcap::write_header(w, "ros2", options_.library);
  for (const auto& schema : summary.schemas)
    mcap::write_schema(w, schema);
  for (const auto& channel : summary.channels)
    mcap::write_channel(w, channel);
  {
    const std::size_t at = w.size();
    mcap::write_metadata(w, "pandarcap", metadata_);
    summary.metadata.push_back({at, w.size() - at, "pandarcap"});
  }
  if (!options_.device_name.empty()) {
    const std::size_t at = w.size();
    const std::pair<std::string_view, std::string_view> device[] = {
        {"deviceName", options_.device_name}};
    mcap::write_metadata(w, "foxglove", device);
    summary.metadata.push_back({at, w.size() - at, "foxglove"});
  }
  {
    const std::size_t at = w.size();
    const auto csv =
        std::span(reinterpret_cast<const std::uint8_t*>(options_.calibration_csv.data()),
                  options_.calibration_csv.size());
    mcap::write_attachment(w, create_time_ns, create_time_ns, "calibration.csv", "text/csv", csv);
    summary.attachments.push_back({at, w.size() - at, create_time_ns, create_time_ns, csv.size(),
                                   "calibration.csv", "text/csv"});
  }
  // Padded to a whole block, so every chunk after it starts on one.
  const std::size_t padding = mcap::padding_bytes(w.size(), kDirectIoBlock);
  out_.resize(out_.size() + padding);  // within the reserved capacity: no allocation
  mcap::write_padding(std::span(out_).last(padding));
  slot.whole_bytes = 0;
  // Past the page cache too, from block-aligned memory: were they in the page cache behind
  // chunks on the disk, a power cut could leave a file whose chunks are there and whose header
  // is not.
  if (slot.file.direct() && out_.size() > opening_capacity_) {
    slot.file.end_direct();  // never expected (out_ outgrew its reserve): not direct
  }
  std::span<const std::uint8_t> opening(out_);
  if (slot.file.direct()) {
    std::memcpy(opening_.get(), out_.data(), out_.size());
    opening = std::span<const std::uint8_t>(opening_.get(), out_.size());
  }
  if (const io::IoError error = write_out(slot, opening)) io::throw_io_error(error);
  if (open_ == nullptr) open_ = pipeline_.take_free();
}

bool McapFile::make_room(std::size_t data_bytes, std::uint16_t channel) {
  if (data_bytes > max_message_bytes_) {
    throw std::length_error("MCAP message larger than the configured frame capacity");
  }
  count_done_chunks();
  if (open_ != nullptr && open_->messages != 0) {
    const bool too_big =
        open_->records.size() + mcap::kMessagePrefixBytes + data_bytes > open_->records.capacity();
    const bool over = open_->records.size() >= options_.chunk_bytes;
    if (too_big || over || open_->index[channel - 1].size() >= max_index_entries_) {
      open_->full = true;
      submit_open();
    }
  }
  if (open_ == nullptr) open_ = pipeline_.take_free();
  if (open_ == nullptr && options_.wait_for_free_chunk) {
    if (ChunkBuffer* oldest = pipeline_.wait_done()) take_back(*oldest);
    open_ = pipeline_.take_free();
  }
  if (open_ != nullptr) return true;
  ++not_recorded_;
  return false;
}

bool McapFile::begin_message(std::uint16_t channel, std::uint64_t log_time,
                             std::size_t data_bytes) {
  if (!make_room(data_bytes, channel)) return false;
  ChunkBuffer& chunk = *open_;
  if (chunk.messages == 0 || log_time < chunk.start_time) chunk.start_time = log_time;
  if (chunk.messages == 0 || log_time > chunk.end_time) chunk.end_time = log_time;
  ++chunk.messages;
  chunk.index[channel - 1].push_back({log_time, chunk.records.size()});
  mcap::ByteWriter w(chunk.records);
  mcap::write_message_prefix(w, channel, sequence_[channel]++, log_time, log_time, data_bytes);
  return true;
}

void McapFile::submit_open() {
  Slot& slot = *now_;
  slot.messages_in_flight += open_->messages;
  slot.bytes_in_flight += open_->records.size();
  ++slot.chunks_in_flight;
  open_->fd = slot.file.fd();
  open_->file = slot.number;
  pipeline_.submit(open_);
  open_ = nullptr;
}

bool McapFile::add_frame(const Frame& frame, std::uint64_t log_time) {
  const PcdLayout layout = options_.format.layout;
  const std::size_t prefix = mcap::pointcloud2_prefix_bytes(options_.frame_id.size(), layout);
  const std::size_t data = frame.size * pcd_point_bytes(layout);
  // A daemon arena holds its points in the output layout already: its bytes go in as they are.
  const bool as_is = frame.is_encoded() && frame.format.layout == layout &&
                     frame.format.axes == options_.format.axes;
  if (frame.is_encoded() && !as_is) {
    throw std::invalid_argument("MCAP frame layout differs from the PCD's");
  }
  if (!begin_message(kPointsChannel, log_time, prefix + data + mcap::kPointCloud2SuffixBytes)) {
    return false;
  }
  std::vector<std::uint8_t>& records = open_->records;
  mcap::ByteWriter w(records);
  mcap::write_pointcloud2_prefix(w, mcap::ros_time(frame.info.start_ns), options_.frame_id,
                                 static_cast<std::uint32_t>(frame.size), layout);
  if (as_is) {
    w.bytes(frame.used_bytes());  // within the reserved capacity: no allocation
  } else {
    const std::size_t at = records.size();
    records.resize(at + data);  // within the reserved capacity: no allocation
    encode_pcd_points(frame.used(), std::span(records.data() + at, data), options_.format,
                      PcdFrameContext{frame.info.start_ns, frame.info.return_mode});
  }
  mcap::write_pointcloud2_suffix(w);
  return true;
}

bool McapFile::add_packet(std::span<const std::uint8_t> payload, std::int64_t receive_time_ns,
                          std::uint64_t log_time) {
  if (!begin_message(kPacketsChannel, log_time, mcap::pandar_packet_bytes(payload.size()))) {
    return false;
  }
  mcap::ByteWriter w(open_->records);
  mcap::write_pandar_packet(w, mcap::ros_time(receive_time_ns), payload);
  return true;
}

bool McapFile::add_health(std::string_view json, std::uint64_t log_time) {
  while (!json.empty() && json.back() == '\n')
    json.remove_suffix(1);
  if (!begin_message(kHealthChannel, log_time, json.size())) return false;
  mcap::ByteWriter(open_->records).bytes(json);
  return true;
}

void McapFile::count_done_chunks() {
  while (ChunkBuffer* chunk = pipeline_.take_done())
    take_back(*chunk);
}

void McapFile::take_back(ChunkBuffer& chunk) {
  if (closing_ != nullptr && chunk.file == closing_->number) {
    take_closing(chunk);
  } else if (Leaving* leaving = leaving_of(chunk)) {
    take_leaving(*leaving, chunk);
  } else {
    count_chunk(chunk);
  }
}

void McapFile::take_closing(ChunkBuffer& chunk) noexcept {
  if (const io::IoError error = count_into(*closing_, chunk); error && !closed_.error) {
    closed_.error = error;
  }
  settle_closing();
}

McapFile::Leaving* McapFile::leaving_of(const ChunkBuffer& chunk) noexcept {
  if (leaving_count_ == 0) return nullptr;
  for (Leaving& leaving : leaving_) {
    if (leaving.chunks_in_flight != 0 && leaving.number == chunk.file) return &leaving;
  }
  return nullptr;
}

void McapFile::take_leaving(Leaving& leaving, ChunkBuffer& chunk) noexcept {
  // Its messages were counted lost when it was let go: whether the chunk was written or not,
  // it is not counted, and the file ends on its last whole chunk counted before. What it says
  // of the pipeline and the disk still counts, as for any chunk written.
  const bool written = !chunk.failed && chunk.write_error == 0;
  if (written && chunk.uncompressed) ++chunks_uncompressed_;
  if (written && chunk.direct_refused) direct_works_ = false;  // the next file from its start
  pipeline_.give_back(&chunk);
  if (--leaving.chunks_in_flight != 0) return;
  leaving.file.truncate(leaving.whole_bytes);
  (void)leaving.file.try_close();  // the file is gone: nothing more to report
  --leaving_count_;
}

void McapFile::count_chunk(ChunkBuffer& chunk) {
  if (chunk.failed) {
    // Not written: the compressor threw (never expected). Its text before the buffer is free.
    const std::runtime_error error(chunk.error.data());
    (void)count_into(*now_, chunk);
    throw error;
  }
  if (const io::IoError error = count_into(*now_, chunk)) io::throw_io_error(error);
}

io::IoError McapFile::count_into(Slot& slot, ChunkBuffer& chunk) noexcept {
  // Whatever happens, the buffer is free again; its messages stay in slot.messages_in_flight
  // until counted as written, so a failure counts them as lost.
  struct GiveBack {
    ChunkPipeline& pipeline;
    ChunkBuffer& chunk;
    ~GiveBack() { pipeline.give_back(&chunk); }
  } give_back{pipeline_, chunk};
  --slot.chunks_in_flight;
  OutputFile& file = slot.file;
  if (chunk.failed) return {EIO, "cannot compress a chunk for", file.path()};
  if (chunk.write_error != 0) {
    // What the write thread wrote of it, if anything, is cut off: the file ends on the chunk
    // before, the last one counted (the write thread writes nothing of this file after it).
    file.truncate(slot.whole_bytes);
    return {chunk.write_error, "cannot write", file.path()};
  }
  if (chunk.direct_refused) {
    // Through the page cache from this chunk on (the write thread ended O_DIRECT on the
    // descriptor), and every later file from its start.
    direct_works_ = false;
    file.end_direct();
  }
  // The compression thread framed the chunk (its record, its indexes, the padding) and the write
  // thread appended it: it starts where the chunks before it, in the order submitted, ended.
  const std::uint64_t chunk_start = file.size();
  mcap::ChunkInfo info;
  info.message_start_time = chunk.start_time;
  info.message_end_time = chunk.end_time;
  info.chunk_start_offset = chunk_start;
  info.chunk_length = chunk.record_bytes;
  info.compression = chunk.compression;
  info.compressed_size = chunk.stored_bytes;
  info.uncompressed_size = chunk.records.size();
  for (std::size_t c = 0; c < mcap::kMaxChannels; ++c) {
    if (chunk.index_at[c] != 0) info.message_index_offset[c] = chunk_start + chunk.index_at[c];
  }
  info.message_index_length = chunk.index_bytes;
  file.count_written(chunk.written_bytes);
  slot.whole_bytes = file.size();
  slot.summary.chunks.push_back(info);  // within the reserved capacity (full())
  for (std::size_t c = 0; c < mcap::kMaxChannels; ++c) {
    for (const auto& entry : chunk.index[c])
      slot.summary.count_message(static_cast<std::uint16_t>(c + 1), entry.log_time);
  }
  slot.messages_in_flight -= chunk.messages;
  slot.bytes_in_flight -= chunk.records.size();
  if (chunk.uncompressed) ++chunks_uncompressed_;
  return {};
}

io::IoError McapFile::write_out(Slot& slot, std::span<const std::uint8_t> bytes) noexcept {
  OutputFile& file = slot.file;
  io::IoError error = file.try_write(bytes);
  if (error && error.code == EINVAL && file.direct()) {
    // A file system that opens with O_DIRECT but refuses the writes: the page cache, for this
    // file and every one after it.
    direct_works_ = false;
    file.end_direct();
    file.truncate(slot.whole_bytes);
    error = file.try_write(bytes);
  }
  if (error) {
    file.truncate(slot.whole_bytes);
    return error;
  }
  slot.whole_bytes = file.size();
  return {};
}

void McapFile::make_tail(const Slot& slot) {
  out_.clear();
  mcap::ByteWriter w(out_);
  mcap::write_tail(w, slot.file.size(), slot.summary);  // within out_'s reserve
}

io::IoError McapFile::finish_whole(Slot& slot, bool cut) noexcept {
  OutputFile& file = slot.file;
  if (!file.is_open()) return {EBADF, "cannot finish", file.path()};
  // A failed chunk's bytes may be on the disk past the last whole chunk (size() never counted
  // them): cut off, or the tail would not end the file.
  if (cut && !file.truncate(slot.whole_bytes)) {
    return {errno != 0 ? errno : EIO, "cannot cut back", file.path()};
  }
  try {
    make_tail(slot);
  } catch (...) {
    return {ENOMEM, "cannot finish", file.path()};  // never expected: out_ holds the largest
  }
  file.end_direct();  // the tail ends where it ends: through the page cache
  return write_out(slot, out_);
}

void McapFile::settle_closing() noexcept {
  if (closing_ == nullptr || closed_ready_ || closing_->chunks_in_flight != 0) return;
  Slot& slot = *closing_;
  // Its tail after its last whole chunk: after a chunk that failed too (cut back first), and a
  // tail that failed once is tried again from there, as the next start's recovery would.
  io::IoError error = finish_whole(slot, static_cast<bool>(closed_.error));
  if (error && !closed_.error) {
    closed_.error = error;
    error = finish_whole(slot, true);
  }
  closed_.finished = !error;
  if (const io::IoError close_error = slot.file.try_close()) {
    // A close that reports a deferred write error: what was written may not all be there.
    if (!closed_.error) closed_.error = close_error;
    closed_.finished = false;
  }
  closed_.messages = slot.summary.message_count;
  closed_.messages_lost = slot.messages_in_flight;
  closed_.bytes_lost = slot.bytes_in_flight;
  closed_ready_ = true;
}

void McapFile::flush() {
  if (!now_->file.is_open()) return;
  count_done_chunks();
  if (open_ != nullptr && open_->messages != 0) submit_open();
}

void McapFile::drain() {
  if (!now_->file.is_open() && closing_ == nullptr && leaving_count_ == 0) return;
  while (ChunkBuffer* chunk = pipeline_.wait_done())
    take_back(*chunk);
}

void McapFile::close() {
  if (!now_->file.is_open()) return;
  flush();
  drain();
  if (const io::IoError error = finish_whole(*now_, false)) io::throw_io_error(error);
  now_->file.close();
}

void McapFile::close_later() {
  if (!now_->file.is_open()) return;
  if (closing_ != nullptr) throw std::logic_error("McapFile::close_later: a file still closes");
  flush();
  closing_ = now_;
  now_ = now_ == &slots_[0] ? &slots_[1] : &slots_[0];
  closed_ = {};
  closed_ready_ = false;
  settle_closing();  // nothing in flight: finished now
}

void McapFile::finish_closing() noexcept {
  // The chunks come back in the order submitted: the closing file's before any of the next.
  while (closing_ != nullptr && !closed_ready_) {
    ChunkBuffer* chunk = pipeline_.wait_done();
    if (chunk == nullptr) break;  // never expected: its chunks counted as in flight
    if (Leaving* leaving = leaving_of(*chunk)) {
      take_leaving(*leaving, *chunk);  // a file let go before it
    } else {
      take_closing(*chunk);
    }
  }
}

bool McapFile::take_closed(McapClosedFile& closed) noexcept {
  if (closing_ == nullptr || !closed_ready_) return false;
  closed = closed_;
  closing_ = nullptr;
  closed_ready_ = false;
  return true;
}

std::uint64_t McapFile::abandon(bool* finished) noexcept {
  Slot& slot = *now_;
  std::uint64_t lost = slot.messages_in_flight;
  if (open_ != nullptr) {
    lost += open_->messages;
    open_->clear();
  }
  // This file's chunks in flight are waited for (the write thread holds its descriptor until
  // they are back); a closing file's before them are counted into it on the way.
  while (slot.chunks_in_flight > 0) {
    ChunkBuffer* chunk = pipeline_.wait_done();
    if (chunk == nullptr) break;  // never expected: counted as in flight
    if (closing_ != nullptr && chunk->file == closing_->number) {
      take_closing(*chunk);
    } else if (Leaving* leaving = leaving_of(*chunk)) {
      take_leaving(*leaving, *chunk);
    } else {
      --slot.chunks_in_flight;
      pipeline_.give_back(chunk);
    }
  }
  slot.messages_in_flight = 0;
  slot.bytes_in_flight = 0;
  slot.chunks_in_flight = 0;
  const bool whole = finished != nullptr && !finish_whole(slot, true);
  if (finished != nullptr) *finished = whole;
  if (!whole) slot.file.truncate(slot.whole_bytes);
  (void)slot.file.try_close();  // a file that failed already: nothing more to report
  return lost;
}

std::uint64_t McapFile::let_go() noexcept {
  Slot& slot = *now_;
  Leaving* free = nullptr;
  for (Leaving& leaving : leaving_) {
    if (leaving.chunks_in_flight == 0) free = &leaving;
  }
  if (slot.chunks_in_flight == 0 || free == nullptr) return abandon();  // nothing to wait for
  std::uint64_t lost = slot.messages_in_flight;
  if (open_ != nullptr) {
    lost += open_->messages;
    open_->clear();
  }
  // The descriptor goes aside with what its chunks need; the slot keeps a closed file, ready
  // for the next open().
  free->file.swap(slot.file);
  free->number = slot.number;
  free->whole_bytes = slot.whole_bytes;
  free->chunks_in_flight = slot.chunks_in_flight;
  ++leaving_count_;
  slot.messages_in_flight = 0;
  slot.bytes_in_flight = 0;
  slot.chunks_in_flight = 0;
  return lost;
}

}  // namespace pandarcap
