#include "daemon/pipeline.hpp"

#include <pthread.h>

#include <latch>

#include "daemon/daemon_options.hpp"

namespace pandarcap {
namespace {

std::size_t power_of_two_at_least(std::size_t n) {
  std::size_t p = 1;
  while (p < n)
    p <<= 1;
  return p;
}

}  // namespace

Pipeline::Pipeline(const DaemonConfig& c, std::uint32_t points_per_frame)
    : ring(c.ring.slots),
      arena_memory(c.arenas.count * FrameArena::bytes_for(points_per_frame, pcd_format(c))),
      free_arenas(power_of_two_at_least(c.arenas.count)),
      free_raw(power_of_two_at_least(raw_batches(c))),
      to_writer(power_of_two_at_least(c.arenas.count + raw_batches(c) + 16)),
      status(4) {
  const std::size_t arena_bytes = FrameArena::bytes_for(points_per_frame, pcd_format(c));
  for (std::uint32_t i = 0; i < c.arenas.count; ++i) {
    arenas.push_back(std::make_unique<FrameArena>(arena_memory.data() + i * arena_bytes,
                                                  points_per_frame, pcd_format(c)));
    free_arenas.try_push(arenas.back().get());
  }
  for (std::uint32_t i = 0; i < raw_batches(c); ++i) {
    raw.push_back(std::make_unique<RawBatch>(c.arenas.packets_per_frame));
    free_raw.try_push(raw.back().get());
  }
}

void PipelineThreads::start(const char* name, std::function<void()> setup,
                            std::function<void()> body, std::function<void()> stop) {
  // Room first: a vector that failed to grow after the thread started would join it unasked.
  started_.reserve(started_.size() + 1);
  std::latch placed(1);
  started_.push_back(
      Started{std::move(stop),
              std::jthread([name, &placed, setup = std::move(setup), body = std::move(body)] {
                pthread_setname_np(pthread_self(), name);
                if (setup) setup();
                placed.count_down();  // `placed` is not touched after this: start() returns
                body();
              })});
  placed.wait();
}

void PipelineThreads::stop_all() noexcept {
  while (!started_.empty()) {
    Started& last = started_.back();
    if (last.stop) last.stop();
    if (last.thread.joinable()) last.thread.join();
    started_.pop_back();
  }
}

}  // namespace pandarcap
