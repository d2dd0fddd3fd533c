// What the daemon's threads hand each other, all allocated once at start-up:
//
//   receive/replay --PacketRing--> decode worker --SpscQueue<WriterMessage>--> writer
//                                        ^                                       |
//                                        +---- SpscQueue<FrameArena*> ----------+  (empty arenas)
//                                        +---- SpscQueue<RawBatch*>   ----------+  (empty batches)
//
// A FrameArena is one frame's fixed point storage, in the output layout (PCD and MCAP): the decode
// worker encodes each point into it once, and the writer persists its bytes as they are. A RawBatch
// is a run of raw datagrams, copied out of the ring, on their way to the pcap recording. When no
// empty arena (or batch) is there, the decode worker drops the frame (or the datagram's recording)
// and counts it: it never allocates and never waits for the writer.
#pragma once

#include <netinet/in.h>

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <memory>
#include <new>
#include <optional>
#include <span>
#include <type_traits>

#include "core/decode/stream_decoder.hpp"
#include "core/frames/frame.hpp"
#include "core/frames/point.hpp"
#include "core/health/latency_histogram.hpp"
#include "core/sensors/packet.hpp"
#include "daemon/io/file_output.hpp"
#include "daemon/packet_slot.hpp"
#include "daemon/streaming_copy.hpp"
#include "ringbuf/spsc_queue.hpp"

namespace pandarcap {

struct FrameArena {
  // The bytes an arena of `capacity_points` takes: whole O_DIRECT blocks, so that arenas laid one
  // after another in one ArenaMemory (Pipeline) all start aligned to them, and the writer hands
  // the points to the kernel without a copy.
  static std::size_t bytes_for(std::size_t capacity_points, PcdFormat format) noexcept {
    return whole_direct_blocks(capacity_points * pcd_point_bytes(format.layout));
  }
  // `memory`: bytes_for() bytes, aligned to kDirectIoBlock, zero-filled (ArenaMemory's), not
  // owned.
  FrameArena(std::uint8_t* memory, std::size_t capacity_points, PcdFormat format)
      : capacity(capacity_points) {
    frame.encoded = std::span(memory, capacity * pcd_point_bytes(format.layout));
    frame.format = format;
  }
  std::size_t capacity;
  Frame frame;
  // Kernel receive time (CLOCK_REALTIME ns) of the packet whose arrival finished the frame: the
  // start of the frame latency the writer measures. 0: not measured (replay).
  std::int64_t completed_receive_ns = 0;
  // The same packet's receive time by the source's clock, in every run: the host's (live) or
  // the capture's record time (replay); for a frame the shutdown finished, the last packet's.
  // MCAP messages are logged at it, so a converted capture plays back at its recorded pace.
  std::int64_t completed_log_ns = 0;
};

// What a recorded datagram carries besides its bytes. Whole lines: the decoder builds it aside
// and streams it into the batch (daemon/streaming_copy.hpp), as it does the payload.
struct alignas(ringbuf::kCacheLine) RawPacketHeader {
  std::int64_t receive_time_ns = 0;
  SlotAddress source{};
  SlotAddress destination{};            // as the wire carried it (PacketSlot::destination)
  std::uint16_t length = 0;             // bytes in payload (a truncated datagram keeps what fit)
  std::uint32_t original_length = 0;    // bytes the datagram had (more than length: it was cut)
  std::uint8_t wire_header_length = 0;  // PacketSlot::wire_header: 0 = synthesise the headers
  std::uint8_t wire_header[kWireHeaderCapacity];
  std::uint16_t wire_trailer_length = 0;  // PacketSlot::wire_trailer_length
  std::uint32_t wire_length = 0;          // PacketSlot::wire_length
};
static_assert(std::is_trivially_copyable_v<RawPacketHeader>);
static_assert(sizeof(RawPacketHeader) % kStreamingGranule == 0);

struct RawPacket : RawPacketHeader {
  // Line-aligned, of a capacity in whole 16-byte granules: streamed in as they are.
  alignas(ringbuf::kCacheLine) std::uint8_t payload[PacketSlot::kPayloadCapacity];
};
static_assert(PacketSlot::kPayloadCapacity % kStreamingGranule == 0);

struct RawBatch {
  explicit RawBatch(std::size_t capacity_packets)
      : packets(new RawPacket[capacity_packets]), capacity(capacity_packets) {}
  std::unique_ptr<RawPacket[]> packets;
  std::size_t capacity;
  std::size_t size = 0;
};

// The decode worker's counters, copied to the writer once a second (and at the end) as one
// message, so the writer reads a consistent set without any shared mutable state.
struct DecodeSnapshot {
  StreamStats stream;
  SequenceStats sequence;
  AssemblerStats frames;
  std::uint64_t frames_decimated = 0;
  std::uint64_t frames_fragment = 0;      // partial frames too small to write
  std::uint64_t raw_packets_dropped = 0;  // no empty RawBatch: not in the pcap nor the MCAP
  std::int64_t monotonic_ns = 0;  // when it was taken (the last packet's time is in DecodeLive)
  LatencyHistogram latency;       // kernel receive timestamp -> decoded (live sources only)
  // The last accepted packet's time minus its receive time (see HealthGauges); none before one.
  std::optional<std::int64_t> sensor_clock_offset_ns;
  SensorModelId model = SensorModelId::kPandar40P;  // whose decoder runs
};

// Messages are copied into the queue's preallocated cells; a snapshot travels by value.
struct WriterMessage {
  enum class Kind : std::uint8_t { kFrame, kRaw, kSnapshot, kEnd } kind = Kind::kEnd;
  FrameArena* arena = nullptr;  // kFrame
  RawBatch* raw = nullptr;      // kRaw
  DecodeSnapshot snapshot;      // kSnapshot and kEnd (the final counts)
};

// The queues between the decode worker and the writer, sized from the configuration at start-up.
using WriterQueue = ringbuf::SpscQueue<WriterMessage>;  // frames, raw batches, snapshots, the end
using ArenaQueue = ringbuf::SpscQueue<FrameArena*>;     // empty arenas, back to the decoder
using RawQueue = ringbuf::SpscQueue<RawBatch*>;         // empty raw batches, back to the decoder

// Per-loop progress counters for the systemd watchdog: each loop bumps its own every iteration,
// including idle wake-ups, so "not advancing" means stuck, not "no packets".
struct Heartbeats {
  std::atomic<std::uint64_t> receive{0};
  std::atomic<std::uint64_t> decode{0};
  std::atomic<std::uint64_t> writer{0};
};

// What the writer reads from the decoder at its own moments rather than from the once-a-second
// counter snapshot. Written only by the decode thread.
// - When the decoder last took a packet (CLOCK_MONOTONIC ns, 0 = never; a replay's only: live,
//   the receiver's ReceiveCounters::last_arrival_monotonic_ns says it), stored once per batch:
//   the writer reads it at every wake-up (at least every 100 ms), so silence and its end show in
//   the health within a tenth of a second of the no-data timeout instead of up to a second later.
// - The decoder's returns from its wait on the ring: read at each health tick, so its wake-ups
//   per second cover the same second as the receive thread's and the writer's. (From the
//   snapshot, the window lagged the tick by up to a second and could miss a short burst.)
struct DecodeLive {
  std::atomic<std::int64_t> last_packet_monotonic_ns{0};
  std::atomic<std::uint64_t> wakeups{0};
};

// One turn of a source that the decode thread reads itself (the packet ring, between batches):
// it took packets into the ring, or waited for some (a wake-up), or has ended.
enum class ReceiveTurn : std::uint8_t { kTook, kWaited, kEnded };

// Written only by the receive (or replay) thread, read by the writer for health.
// The receive, decode and writer loops count heap allocations (see allocation_counter.hpp) from
// this long after they start: the first frame, file and health record are behind them by then.
inline constexpr std::int64_t kWarmUpNs = 2'000'000'000;
// The decoder hands its packets to the writer (pcap, MCAP) at least this often.
inline constexpr std::int64_t kRecordingFlushNs = 100'000'000;

struct ReceiveCounters {
  std::atomic<std::uint64_t> datagrams{0};
  std::atomic<std::uint64_t> bytes{0};
  std::atomic<std::uint64_t> foreign{0};
  // The source lock's (core/decode/source_lock.hpp): valid Pandar packets from another source (also
  // in `foreign`), the times the lock moved, and the sources as pack_ipv4_source (0: none yet).
  std::atomic<std::uint64_t> other_sensor{0};
  std::atomic<std::uint64_t> source_changes{0};
  std::atomic<std::uint64_t> sensor_source{0};
  std::atomic<std::uint64_t> other_source{0};
  std::atomic<std::uint64_t> truncated{0};
  std::atomic<std::uint64_t> kernel_drops{0};
  std::atomic<std::uint64_t> ring_overruns{0};
  std::atomic<std::uint64_t> receive_errors{0};
  std::atomic<std::uint64_t> wakeups{0};  // returns from the receive thread's wait
  // Live sources: when the newest datagram taken from the kernel arrived (CLOCK_MONOTONIC ns, 0 =
  // none yet; from its kernel timestamp, see arrival_on_monotonic), for the health's last packet:
  // the receiver sees arrivals as they come, a decoder working through a backlog would not.
  std::atomic<std::int64_t> last_arrival_monotonic_ns{0};
  // Every datagram that arrived before `seen_until` (CLOCK_MONOTONIC ns, 0 = none yet) has been
  // seen by a look, or its arrival noted from the kernel's drop count (a queue that filled holds
  // only what arrived until then). Set at each look that leaves nothing unseen behind it, less
  // what the kernel may still hold unseen (the packet ring's block being filled); the receiver
  // looks again within `look_interval_ns` while it runs. The writer says no_data only while
  // this is that current (Writer::silence_at): after a pause of the process, or a receiver that
  // fell behind, the newest arrival seen is not the sensor's last packet; the record then waits
  // a second for a look, and past that says the receiver is behind.
  std::atomic<std::int64_t> seen_until_monotonic_ns{0};
  std::atomic<std::int64_t> look_interval_ns{0};
  // A live source's start (CLOCK_MONOTONIC ns; 0: a replay, which makes no looks), set before
  // the writer starts: until the receiver's first look, what it has seen reaches back to here.
  std::atomic<std::int64_t> listening_since_monotonic_ns{0};
  // When the receiver saw the stop (CLOCK_MONOTONIC ns, 0 = running): it listens no further
  // (a drain takes what the kernel holds), so a silence is measured up to it. A sensor that
  // sent on is not known to have gone quiet because the daemon stopped listening.
  std::atomic<std::int64_t> stopped_listening_monotonic_ns{0};
  void note_stop(std::int64_t monotonic_ns) noexcept {
    if (stopped_listening_monotonic_ns.load(std::memory_order_relaxed) == 0)
      stopped_listening_monotonic_ns.store(monotonic_ns, std::memory_order_relaxed);
  }
  // Release: a writer that sees it (acquire) sees the arrivals noted before it.
  void note_seen_until(std::int64_t monotonic_ns, std::int64_t interval_ns) noexcept {
    look_interval_ns.store(interval_ns, std::memory_order_relaxed);
    seen_until_monotonic_ns.store(monotonic_ns, std::memory_order_release);
  }
  void note_arrival(std::int64_t monotonic_ns) noexcept {
    if (monotonic_ns > last_arrival_monotonic_ns.load(std::memory_order_relaxed))
      last_arrival_monotonic_ns.store(monotonic_ns, std::memory_order_relaxed);
  }
  // A replay's damage (daemon/source/replay_source.hpp), for the health: a replay that met any
  // says so in every record from then on, the last one included. Records whose headers are
  // damaged (skipped), MCAP chunks skipped by the chunk index with the packets they held, and
  // MCAP records read over (a damaged length).
  std::atomic<std::uint64_t> capture_records_malformed{0};
  std::atomic<std::uint64_t> capture_chunks_skipped{0};
  std::atomic<std::uint64_t> capture_packets_skipped{0};
  std::atomic<std::uint64_t> capture_records_damaged{0};
  // The first damage read over, and how the file ended when it did not end whole: each written
  // once, by the replay thread, before `capture_damage_named` (first) or `capture_end` (the end)
  // is stored with release; read by the writer only after it loads that flag with acquire.
  static constexpr std::size_t kDamageTextBytes = 384;
  char capture_first_damage[kDamageTextBytes] = {};
  std::atomic<bool> capture_damage_named{false};
  enum class CaptureEnd : std::uint8_t { kRunning, kWhole, kTruncated, kDamaged };
  char capture_end_text[kDamageTextBytes] = {};
  std::atomic<CaptureEnd> capture_end{CaptureEnd::kRunning};

  // Single writer: a relaxed load + store is enough (no read-modify-write needed).
  static void add(std::atomic<std::uint64_t>& counter, std::uint64_t n) noexcept {
    counter.store(counter.load(std::memory_order_relaxed) + n, std::memory_order_relaxed);
  }
  // The source lock's state, as the health reads it (after each batch).
  void publish_sources(std::uint64_t sensor, std::uint64_t other, std::uint64_t changes) noexcept {
    sensor_source.store(sensor, std::memory_order_relaxed);
    other_source.store(other, std::memory_order_relaxed);
    source_changes.store(changes, std::memory_order_relaxed);
  }
};

}  // namespace pandarcap
