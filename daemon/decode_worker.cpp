#include "daemon/decode_worker.hpp"

#include <time.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <thread>
#include <utility>

#include "core/sensors/model_detection.hpp"
#include "core/sensors/sensor_model.hpp"
#include "core/sensors/sensor_models.hpp"
#include "daemon/allocation_counter.hpp"
#include "daemon/clocks.hpp"

namespace pandarcap {
namespace {

constexpr std::size_t kDecodeBatch = 64;
// The writer writes health on its own 1 s tick from the latest snapshot: one a second, out of
// phase, left a record up to a second behind the stream (a motor stop said after 2 s). Ten a
// second keep every record within 0.1 s of it.
constexpr std::int64_t kSnapshotIntervalNs = kRecordingFlushNs;
// The longest a live source waits for the writer in one stretch, whatever room is upstream: a
// writer gone for longer (a disk that does not answer) gets the old behaviour, frames dropped
// and counted, and the stall report says why.
constexpr std::int64_t kLongestWriterWaitNs = 1'000'000'000;
// After a stop, what is upstream waits for a slow writer this long in all, not the backlog's
// length at the writer's pace (a million-slot ring on a slow disk would outlast systemd's
// TimeoutStopSec): the rest is dropped and counted.
constexpr std::int64_t kLongestStopWaitNs = 5'000'000'000;
// Each wait's slice: the writer wakes this thread when it returns an arena or batch; the slice
// only bounds how late a full upstream is noticed.
constexpr auto kWriterWaitSlice = std::chrono::milliseconds(1);

}  // namespace

DecodeWorker::DecodeWorker(const Calibration& calibration, const DecodeWorkerOptions& options,
                           PacketRing& ring, WriterQueue& to_writer, ArenaQueue& free_arenas,
                           RawQueue& free_raw)
    : options_(options),
      ring_(ring),
      to_writer_(to_writer),
      free_arenas_(free_arenas),
      free_raw_(free_raw),
      calibration_(calibration),
      decoder_(options.model, calibration, options.decoder, *this),
      detecting_(options.detect_model) {}

void DecodeWorker::choose_model(SensorModelId model) {
  const bool own = calibration_.channel_count == channel_count(model);
  const StreamStats before = decoder_.stats();
  decoder_.choose(model, own ? calibration_ : Calibration::nominal(model), options_.decoder, *this);
  decoder_.visit([&](auto& d) { d.count_before(before); });
}

template <class Decoder>
std::size_t DecodeWorker::process_batch(Decoder& decoder, std::span<const PacketSlot> batch,
                                        std::size_t from) {
  for (std::size_t i = from; i < batch.size(); ++i) {
    const PacketSlot& slot = batch[i];
    if (detecting_ && !slot.truncated) {
      if (decoder.stats().accepted > 0) {
        detecting_ = false;  // the model is the stream's now
      } else {
        const DetectedModel d = detect_model(std::span<const std::uint8_t>(
            slot.data(), std::min<std::size_t>(slot.length, sizeof slot.payload)));
        if (d.kind == DetectionKind::kKnown && d.model != Decoder::ModelType::kId) {
          pending_model_ = d.model;
          return i;
        }
      }
    }
    process(decoder, slot);
  }
  return batch.size();
}

double DecodeWorker::single_return_revolution_packets() const {
  return with_model(decoder_.model(), [&]<class M>(std::type_identity<M>) {
    return M::packets_per_revolution(1, options_.expected_rpm);
  });
}

Frame* DecodeWorker::acquire_frame() {
  FrameArena* arena = nullptr;
  // An arena this thread kept back (a fragment, a decimated frame) first: free_arenas_ has one
  // producer, the writer, so this thread never pushes into it.
  if (spares_ > 0) arena = spare_[--spares_];
  while (arena == nullptr && !free_arenas_.try_pop(arena)) {
    if (!wait_for_writer(free_arenas_)) return nullptr;  // the assembler counts the dropped frame
  }
  waiting_since_ns_ = 0;
  for (FrameArena*& open : open_) {
    if (open == nullptr) {
      open = arena;
      return &arena->frame;
    }
  }
  // Cannot happen (the assembler keeps at most two frames open); keep the arena.
  keep_spare(arena);
  return nullptr;
}

void DecodeWorker::keep_spare(FrameArena* arena) noexcept {
  // Room for every arena there is: an arena is in one place at a time.
  if (spares_ < spare_.size()) spare_[spares_++] = arena;
}

void DecodeWorker::frame_done(Frame& frame) {
  FrameArena* arena = nullptr;
  for (FrameArena*& open : open_) {
    if (open != nullptr && &open->frame == &frame) {
      arena = open;
      open = nullptr;
      break;
    }
  }
  if (arena == nullptr) return;
  if (frame.info.partial &&
      (frame.info.azimuth_span_cdeg < options_.min_frame_fraction * kFullCircleCdeg ||
       frame.info.packets < options_.min_frame_fraction * single_return_revolution_packets())) {
    ++frames_fragment_;
    keep_spare(arena);
    return;
  }
  // The packet being decoded is the one whose arrival finished this frame.
  arena->completed_receive_ns = options_.measure_latency ? current_receive_ns_ : 0;
  arena->completed_log_ns = last_receive_ns_;
  const bool write = options_.write_frames && frames_finished_ % options_.frame_decimation == 0;
  ++frames_finished_;
  if (write) {
    WriterMessage message;
    message.kind = WriterMessage::Kind::kFrame;
    message.arena = arena;
    // The queue holds every arena and batch at once, so this cannot fail; if it ever did, the
    // arena goes back to the pool and the frame counts as decimated rather than vanishing.
    if (to_writer_.try_push(message)) {
      to_writer_.notify();
      return;
    }
  }
  ++frames_decimated_;
  keep_spare(arena);
}

void DecodeWorker::record_raw(const PacketSlot& slot) {
  if (raw_ == nullptr) {
    while (!free_raw_.try_pop(raw_)) {
      if (!wait_for_writer(free_raw_)) {
        ++raw_dropped_;
        return;
      }
    }
    waiting_since_ns_ = 0;
  }
  // The batch is read next by the writer, on the other CPU: its lines were that CPU's last, and
  // an ordinary store would first fetch each one. The header is built here and both parts are
  // streamed in whole lines instead (daemon/streaming_copy.hpp).
  RawPacket& packet = raw_->packets[raw_->size++];
  RawPacketHeader header;
  header.receive_time_ns = slot.receive_time_ns;
  header.source = slot.source;
  header.destination = slot.destination;
  header.length =
      static_cast<std::uint16_t>(std::min<std::size_t>(slot.length, sizeof packet.payload));
  header.wire_header_length = slot.wire_header_length;
  if (slot.wire_header_length > 0) {
    std::memcpy(header.wire_header, slot.wire_header, slot.wire_header_length);
    // The frame's trailer follows the payload in the slot (the receiver keeps it in room).
    header.wire_trailer_length = static_cast<std::uint16_t>(
        std::min<std::size_t>(slot.wire_trailer_length, sizeof packet.payload - header.length));
    header.wire_length = slot.wire_length;
  }
  // The recording must not claim bytes it does not hold: a cut datagram keeps its real length.
  header.original_length = slot.truncated
                               ? std::max<std::uint32_t>(slot.original_length, header.length + 1u)
                               : header.length;
  streaming_copy(static_cast<RawPacketHeader*>(&packet), &header, sizeof header);
  streaming_copy(packet.payload, slot.data(), header.length + header.wire_trailer_length);
  if (raw_->size == raw_->capacity) flush_raw();
}

template <class Queue>
bool DecodeWorker::wait_for_writer(Queue& queue) {
  if (options_.lossless) {  // a replay: a file can wait
    queue.wait_for_data(std::chrono::milliseconds(100));
    return true;
  }
  if (upstream_room_ == nullptr) return false;
  const Upstream up = (*upstream_room_)();
  const std::int64_t now = coarse_monotonic_ns();
  if (up.stopping) {
    if (stop_waits_since_ns_ == 0) stop_waits_since_ns_ = now;
    if (now - stop_waits_since_ns_ > kLongestStopWaitNs) return false;
  } else if (!up.room) {
    return false;
  }
  if (waiting_since_ns_ == 0) {
    waiting_since_ns_ = now;
  } else if (now - waiting_since_ns_ > kLongestWriterWaitNs) {
    return false;  // and at once for every frame and datagram, until the writer returns one
  }
  ReceiveCounters::add(*heartbeat_, 1);  // alive: the watchdog should not take this for a hang
  queue.wait_for_data(kWriterWaitSlice);
  return true;
}

void DecodeWorker::flush_raw(bool notify) {
  if (raw_ == nullptr || raw_->size == 0) return;
  WriterMessage message;
  message.kind = WriterMessage::Kind::kRaw;
  message.raw = raw_;
  streaming_stores_done();  // the payloads' stores before the queue's release of the batch
  if (to_writer_.try_push(message)) {
    if (notify) to_writer_.notify();
    raw_ = nullptr;
  } else {
    raw_dropped_ += raw_->size;  // cannot happen (see frame_done); counted if it does
    raw_->size = 0;              // and the batch is reused here (free_raw_ is the writer's to fill)
  }
}

template <class Decoder>
void DecodeWorker::process(Decoder& decoder, const PacketSlot& slot) {
  if (options_.record_raw) record_raw(slot);
  current_receive_ns_ = slot.receive_time_ns;
  last_receive_ns_ = slot.receive_time_ns;
  // A cut datagram (MSG_TRUNC live, snapped in a file) is rejected as bad_length whatever its
  // kept length: an empty payload is exactly that reject. The kept length never exceeds the slot.
  const std::size_t length =
      slot.truncated ? 0 : std::min<std::size_t>(slot.length, sizeof slot.payload);
  const std::uint64_t accepted_before = decoder.stats().accepted;
  decoder.process(std::span<const std::uint8_t>(slot.data(), length));
  // The sensor's clock against this datagram's arrival: for an accepted packet only (a copy
  // arrives later than its original did).
  const StreamStats& stats = decoder.stats();
  if (stats.accepted != accepted_before && stats.last_time_valid && slot.receive_time_ns > 0)
    clock_offset_ns_ = stats.last_t0_ns - slot.receive_time_ns;
}

DecodeSnapshot DecodeWorker::snapshot() const {
  DecodeSnapshot s;
  s.stream = decoder_.stats();
  s.sequence = decoder_.sequence();
  s.frames = decoder_.frames();
  s.model = decoder_.model();
  s.frames_decimated = frames_decimated_;
  s.frames_fragment = frames_fragment_;
  s.raw_packets_dropped = raw_dropped_;
  s.monotonic_ns = coarse_monotonic_ns();
  s.latency = latency_;
  s.sensor_clock_offset_ns = clock_offset_ns_;
  return s;
}

void DecodeWorker::send_snapshot(WriterMessage::Kind kind) {
  WriterMessage message;
  message.kind = kind;
  message.snapshot = snapshot();
  if (kind == WriterMessage::Kind::kEnd) {
    // The end must arrive: wait for the writer to make room (shutdown only).
    while (!to_writer_.try_push(message)) {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
  } else {
    to_writer_.try_push(message);  // a full queue skips one snapshot; the next follows
  }
  to_writer_.notify();
}

void DecodeWorker::run(const std::atomic<bool>& producer_done,
                       std::atomic<std::uint64_t>& heartbeat, DecodeLive& live) {
  // The receive thread fills the ring meanwhile: half of it (and no less than
  // kLeastWaitRoomSlots) is room to wait in. Once the source
  // is done (a stop) nothing fills it, and what it holds waits for the writer rather than be
  // dropped (kLongestStopWaitNs).
  const UpstreamRoom room = [&] {
    return Upstream{
        room_to_wait(ring_.capacity() - ring_.size_approx(), ring_.capacity(), kLeastWaitRoomSlots),
        producer_done.load(std::memory_order_relaxed)};
  };
  upstream_room_ = &room;
  loop(heartbeat, live, [&] {
    // Read the flag before looking at the ring again: if the producer was done then, an empty
    // ring after it means everything has been taken.
    if (producer_done.load(std::memory_order_acquire)) return ReceiveTurn::kEnded;
    ring_.wait_for_data(std::chrono::milliseconds(100));
    return ReceiveTurn::kWaited;
  });
}

void DecodeWorker::run_inline(const ReceiveInline& receive, const UpstreamRoom& room,
                              std::atomic<std::uint64_t>& heartbeat, DecodeLive& live) {
  upstream_room_ = &room;
  loop(heartbeat, live, [&] { return receive(ring_); });
}

template <class Wait>
void DecodeWorker::loop(std::atomic<std::uint64_t>& heartbeat, DecodeLive& live, Wait&& wait) {
  heartbeat_ = &heartbeat;
  std::int64_t next_snapshot_ns = coarse_monotonic_ns();
  const std::int64_t warm_ns = next_snapshot_ns + kWarmUpNs;
  bool hot = false;
  bool ended = false;  // `wait` said nothing more will come: what the ring holds is the last
  for (;;) {
    ReceiveCounters::add(heartbeat, 1);
    std::span<PacketSlot> batch = ring_.peek(kDecodeBatch);
    if (batch.empty()) {
      if (ended) break;
      const ReceiveTurn turn = wait();
      ended = turn == ReceiveTurn::kEnded;
      if (turn == ReceiveTurn::kWaited) ReceiveCounters::add(live.wakeups, 1);
    } else {
      // The model's loop, a batch at a time (no packet pays a branch on the model).
      std::size_t taken = 0;
      while (taken < batch.size()) {
        taken = decoder_.visit([&](auto& d) { return process_batch(d, batch, taken); });
        if (pending_model_) choose_model(*std::exchange(pending_model_, std::nullopt));
      }
      if (options_.measure_latency) {
        // One clock read per batch: "decoded" is when the batch is done.
        const std::int64_t decoded_ns = realtime_ns();
        for (const PacketSlot& slot : batch) {
          if (slot.receive_time_ns > 0) latency_.record(decoded_ns - slot.receive_time_ns);
        }
      } else {
        // A replay: no receiver notes arrivals (ReceiveCounters::last_arrival_monotonic_ns),
        // and a packet is as recent as its taking.
        live.last_packet_monotonic_ns.store(coarse_monotonic_ns(), std::memory_order_relaxed);
      }
      ring_.release(batch.size());
    }
    const std::int64_t now = coarse_monotonic_ns();
    if (!hot && now >= warm_ns) {
      alloc::mark_this_thread_hot(alloc::HotThread::kDecode);
      hot = true;
    }
    if (now >= next_snapshot_ns) {
      // The packets so far (the pcap stays no more than kRecordingFlushNs behind, even at low
      // rates) and the counters, pushed together: one wake-up of the writer for both.
      flush_raw(/*notify=*/false);
      send_snapshot(WriterMessage::Kind::kSnapshot);
      next_snapshot_ns = now + kSnapshotIntervalNs;
    }
  }
  alloc::mark_this_thread_cold();
  upstream_room_ = nullptr;  // the shutdown's frames and batch do not wait on the writer
  // Frames finished by the shutdown, not by a packet: no frame latency to measure.
  current_receive_ns_ = 0;
  decoder_.flush();
  flush_raw();
  send_snapshot(WriterMessage::Kind::kEnd);
}

}  // namespace pandarcap
