// The daemon's pipeline: its fixed memory, and its threads, stopped in the reverse of their start.
//
//   receive/replay --ring--> decode worker --queue--> writer        (see pipeline_types.hpp)
//   the packet ring: the kernel's ring of blocks, read by the decode worker itself
//   (PacketSource::read_by_decoder): no receive thread
//
// Pipeline holds every buffer the threads share, all allocated before the first thread starts
// (config: ring.slots, arenas.count, arenas.points_per_frame, arenas.packets_per_frame).
// PipelineThreads starts them and, whatever way run() leaves (a return, a throw between two
// starts), asks each to stop and joins it, last started first: the simulator, the source, then
// the decoder drains the ring and the writer finishes the files; the sensor status poller, started
// first, stops last, so the final health record's status is not aged by the drain.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <thread>
#include <vector>

#include "config/daemon_config.hpp"
#include "daemon/arena_memory.hpp"
#include "daemon/decode_worker.hpp"
#include "daemon/output/writer.hpp"
#include "daemon/packet_slot.hpp"
#include "daemon/pipeline_types.hpp"
#include "daemon/ptc/sensor_status_channel.hpp"
#include "ringbuf/spsc_queue.hpp"

namespace pandarcap {

struct Pipeline {
  // `points_per_frame`: each arena's (arena_points(), daemon_options.hpp); `ring_slots`: the
  // ring's (ring_slots(), daemon_options.hpp: ring.slots, fewer for the packet ring).
  Pipeline(const DaemonConfig& config, std::uint32_t points_per_frame, std::uint32_t ring_slots);

  // As many raw batches as arenas: the recording may fall behind as far as the frames can.
  static std::uint32_t raw_batches(const DaemonConfig& config) { return config.arenas.count; }

  PacketRing ring;
  ArenaMemory arena_memory;  // every arena's points, one after another
  std::vector<std::unique_ptr<FrameArena>> arenas;
  std::vector<std::unique_ptr<RawBatch>> raw;
  ArenaQueue free_arenas;
  RawQueue free_raw;
  WriterQueue to_writer;
  ringbuf::SpscQueue<StatusLine> status;  // the writer's STATUS= lines for the main thread
  ReceiveCounters receive;
  SensorStatusChannel sensor_status;  // the status poller's answers, for the health record
  DecodeLive live;
  Heartbeats heartbeats;
  std::atomic<bool> stop_source{false};
  std::atomic<bool> source_done{false};             // set by the source thread as it ends
  std::atomic<std::uint32_t> rotate_generation{0};  // SIGHUP
};

class PipelineThreads {
 public:
  PipelineThreads() = default;
  ~PipelineThreads() { stop_all(); }
  PipelineThreads(const PipelineThreads&) = delete;
  PipelineThreads& operator=(const PipelineThreads&) = delete;

  // Starts a thread named `name` (at most 15 characters: `top -H`, /proc/PID/task) that runs
  // `setup` (pinning, priority), then `body`; returns once `setup` is done, so that READY=1
  // after the last start means every thread is named and placed. `stop` is what asks the body to
  // end (nothing for a thread that ends when its input does). Throws std::system_error naming the
  // thread when it cannot be started (a stack or thread limit); those started before it run on
  // until stop_all(), so their inputs must be ended first.
  void start(const char* name, std::function<void()> setup, std::function<void()> body,
             std::function<void()> stop = {});

  // Stops and joins every thread, the last started first. Idempotent.
  void stop_all() noexcept;

 private:
  struct Started {
    std::function<void()> stop;
    std::jthread thread;
  };
  std::vector<Started> started_;
};

}  // namespace pandarcap
