// The decode worker: takes batches of datagrams from the PacketRing, runs each through the core
// StreamDecoder (validate, time, decode, cut frames) into frame arenas from a fixed pool, copies
// each datagram into a RawBatch for the pcap recording, and hands finished arenas and batches to
// the writer. Once a second (and at the end) it sends the writer a snapshot of its counters.
//
// It never allocates. With no empty arena (or raw batch) it waits for the writer to return one
// only while what is upstream can hold more (live: the receive ring, or the kernel's packet ring,
// less than half full; after a stop, and in a replay, always): a writer that falls behind for a
// moment then costs nothing, its backlog waiting where the packets already are. Past that (or a
// second of waiting in one stretch) the frame is dropped (the assembler counts it) and the
// datagram is not recorded (counted), so a writer that stays behind never makes the receive side
// drop instead.
// Every `frame_decimation`-th frame goes to the writer; the others go straight back to the pool,
// counted as decimated.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <functional>
#include <optional>
#include <vector>

#include "core/decode/any_stream_decoder.hpp"
#include "core/decode/calibration.hpp"
#include "core/decode/stream_decoder.hpp"
#include "daemon/packet_slot.hpp"
#include "daemon/pipeline_types.hpp"
#include "ringbuf/spsc_queue.hpp"

namespace pandarcap {

struct DecodeWorkerOptions {
  StreamDecoderConfig decoder;
  // The model decoded from the start (a fixed sensor.model, or the one a replay's first valid
  // packet named), and whether the packets choose it: "auto" on a live source, where the first
  // packet of a known model, before any was accepted, switches to that model's decoder (with the
  // calibration given when it has that model's channels, else the model's nominal table).
  SensorModelId model = SensorModelId::kPandar40P;
  bool detect_model = false;
  std::uint32_t frame_decimation = 1;  // 1 = every frame
  bool write_frames = true;            // false: every frame is returned at once (not written)
  // A partial frame covering less than this fraction of a revolution is a fragment: counted
  // (frames_fragment) and not written, so a stream of discontinuities (a restarting or hostile
  // sender) cannot turn each packet into a file. Covering means both: its blocks span that much
  // azimuth, and it holds that fraction of the packets a revolution has at `expected_rpm` in
  // single-return mode (the fewest a sensor sends: 180 at 600 RPM). Azimuths alone are not
  // enough: packets that jump back and forth can span any angle in a handful. 0 = write every
  // frame.
  double min_frame_fraction = 0.0;
  int expected_rpm = 600;
  bool record_raw = true;
  // Replay: wait for the writer to return a free arena or raw batch instead of dropping the
  // frame. A file can wait; a socket cannot, so live capture drops (and counts) instead.
  bool lossless = false;
  // Live sources: record each packet's kernel receive timestamp -> decoded latency. (A replayed
  // packet's timestamp is its capture time, so the figure would mean nothing.)
  bool measure_latency = false;
};

// The most frame arenas a pool may have (config: arenas.count, 2..64).
inline constexpr std::size_t kMaxArenas = 64;

class DecodeWorker final : public FrameSink {
 public:
  DecodeWorker(const Calibration& calibration, const DecodeWorkerOptions& options, PacketRing& ring,
               WriterQueue& to_writer, ArenaQueue& free_arenas, RawQueue& free_raw);

  // Runs until `producer_done` is set and the ring is empty; then finishes open frames as
  // partial, flushes the raw batch and sends the writer a final snapshot and kEnd.
  // `live` gets the time of each batch taken and the count of wake-ups from the wait.
  void run(const std::atomic<bool>& producer_done, std::atomic<std::uint64_t>& heartbeat,
           DecodeLive& live);

  // A source this thread reads itself, instead of waiting for another thread to fill the ring
  // (the packet ring: the kernel's ring of blocks is then the queue between receive and decode,
  // and one thread wakes per block where two did; daemon/source/packet_source.hpp). Called
  // whenever the ring is empty: puts what has arrived into the ring, waiting for it when
  // nothing has; says which, or that the source has ended.
  using ReceiveInline = std::function<ReceiveTurn(PacketRing&)>;
  // What is upstream, as this thread waits for the writer (see above).
  struct Upstream {
    bool room = false;      // it can hold more while this thread waits
    bool stopping = false;  // a stop was asked (or the source is done): what it holds waits
  };
  using UpstreamRoom = std::function<Upstream()>;
  // Whether a ring of `capacity` units with `free` of them free has room to wait in: more than
  // half of it and more than `least` free. A thread that sleeps wakes late on a busy machine, and
  // what arrives meanwhile needs the room (5 ms late has been seen with two cores shared).
  static bool room_to_wait(std::uint64_t free, std::uint64_t capacity,
                           std::uint64_t least) noexcept {
    return free > std::max(capacity / 2, least);
  }
  // `least` for the receive ring, in slots: 70 ms of a dual-return sensor (a ring of this many
  // or fewer never waits, and drops frames at once, as before the wait).
  static constexpr std::uint64_t kLeastWaitRoomSlots = 512;
  // `least` for the packet ring, in its 32 KiB blocks: about 570 of the 40P's datagrams, 80 ms
  // of a dual-return sensor.
  static constexpr std::uint64_t kLeastWaitRoomBlocks = 24;
  // As run(), reading `receive` for its packets; ends when `receive` has ended and the ring is
  // empty. `live`'s wake-ups are the returns from the source's wait.
  void run_inline(const ReceiveInline& receive, const UpstreamRoom& room,
                  std::atomic<std::uint64_t>& heartbeat, DecodeLive& live);

  // FrameSink (called by the assembler on this thread).
  Frame* acquire_frame() override;
  void frame_done(Frame& frame) override;

 private:
  template <class Decoder>
  void process(Decoder& decoder, const PacketSlot& slot);
  // Decodes batch[from..] with `decoder`; returns where it stopped: the end, or a packet of
  // another model that chooses the decoder (pending_model_).
  template <class Decoder>
  std::size_t process_batch(Decoder& decoder, std::span<const PacketSlot> batch, std::size_t from);
  void choose_model(SensorModelId model);
  // The fewest packets a revolution has (single return at expected_rpm), for the model decoded.
  double single_return_revolution_packets() const;
  void record_raw(const PacketSlot& slot);
  void flush_raw(bool notify = true);
  DecodeSnapshot snapshot() const;
  void send_snapshot(WriterMessage::Kind kind);
  // run()'s and run_inline()'s loop: `wait` waits for the ring to fill (or fills it), and
  // says so (a ReceiveTurn).
  template <class Wait>
  void loop(std::atomic<std::uint64_t>& heartbeat, DecodeLive& live, Wait&& wait);
  // With no arena or raw batch free: waits a little for the writer to return one to `queue` and
  // says so (true: look again), or says the frame or datagram is to be dropped (false).
  template <class Queue>
  bool wait_for_writer(Queue& queue);

  // Set for the loop's life (live sources): see UpstreamRoom.
  const UpstreamRoom* upstream_room_ = nullptr;
  std::atomic<std::uint64_t>* heartbeat_ = nullptr;
  std::int64_t waiting_since_ns_ = 0;     // 0: not waiting for the writer
  std::int64_t stop_waits_since_ns_ = 0;  // the first wait after a stop (0: none yet)

  DecodeWorkerOptions options_;
  PacketRing& ring_;
  WriterQueue& to_writer_;
  ArenaQueue& free_arenas_;
  RawQueue& free_raw_;
  Calibration calibration_;  // as given: used again when the packets choose another model
  AnyStreamDecoder decoder_;
  bool detecting_ = false;  // still choosing the model (see DecodeWorkerOptions::detect_model)
  std::optional<SensorModelId> pending_model_;
  // Arenas currently being filled by the assembler (at most two frames are open at once), so a
  // Frame& from the assembler can be mapped back to its arena without searching the pool.
  std::array<FrameArena*, 4> open_{};
  // Arenas finished without going to the writer (fragments, decimated frames), reused first.
  // free_arenas_ is single-producer (the writer), so they cannot go back there from this thread.
  void keep_spare(FrameArena* arena) noexcept;
  std::array<FrameArena*, kMaxArenas> spare_{};
  std::size_t spares_ = 0;
  RawBatch* raw_ = nullptr;
  std::uint64_t frames_finished_ = 0;
  std::uint64_t frames_decimated_ = 0;
  std::uint64_t frames_fragment_ = 0;
  std::int64_t current_receive_ns_ = 0;  // the packet being decoded (frame latency's start)
  std::int64_t last_receive_ns_ = 0;     // the latest packet's, kept through the shutdown
  // The sensor's clock minus the host's, at the last accepted packet with a valid time and a
  // receive time (the health's sensor_clock_offset_seconds).
  std::optional<std::int64_t> clock_offset_ns_;
  std::uint64_t raw_dropped_ = 0;
  LatencyHistogram latency_;
};

}  // namespace pandarcap
