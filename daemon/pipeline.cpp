#include "daemon/pipeline.hpp"

#include <fmt/format.h>
#include <pthread.h>

#include <latch>
#include <new>
#include <stdexcept>
#include <system_error>

#include "daemon/daemon_options.hpp"

namespace pandarcap {
namespace {

std::size_t power_of_two_at_least(std::size_t n) {
  std::size_t p = 1;
  while (p < n)
    p <<= 1;
  return p;
}

// Between two arenas, and after the last: a block that is no arena's (ArenaMemory::guard), so
// that a write past an arena's end is reported by an ASan build rather than landing in the next.
constexpr std::size_t kArenaGuardBytes = kDirectIoBlock;

std::size_t arena_stride(const DaemonConfig& c, std::uint32_t points_per_frame) {
  return FrameArena::bytes_for(points_per_frame, pcd_format(c)) + kArenaGuardBytes;
}

// The arenas' memory, or an error that names what sizes it (a bare "cannot map" leaves the user
// to guess which of the configuration's keys to lower).
ArenaMemory arena_memory_for(const DaemonConfig& c, std::uint32_t points_per_frame) {
  const PcdFormat format = pcd_format(c);
  const std::size_t bytes = c.arenas.count * arena_stride(c, points_per_frame);
  try {
    return ArenaMemory(bytes);
  } catch (const std::system_error& error) {
    const std::string raised =
        points_per_frame > c.arenas.points_per_frame
            ? fmt::format(", raised from {} to a revolution of the model at sensor.rotation_speed",
                          c.arenas.points_per_frame)
            : "";
    throw std::runtime_error(fmt::format(
        "the frame arenas do not fit: {} arenas x {} points{} x {} bytes ({} MiB; arenas.count, "
        "arenas.points_per_frame and output.pcd_fields size them): {}",
        c.arenas.count, points_per_frame, raised, pcd_point_bytes(format.layout), bytes >> 20,
        error.what()));
  }
}

}  // namespace

// A refused allocation names the keys that size what did not fit: the arenas their own
// (arena_memory_for), the ring and the raw batches here.
Pipeline::Pipeline(const DaemonConfig& c, std::uint32_t points_per_frame,
                   std::uint32_t ring_slots) try
    : ring(ring_slots),
      arena_memory(arena_memory_for(c, points_per_frame)),
      free_arenas(power_of_two_at_least(c.arenas.count)),
      free_raw(power_of_two_at_least(raw_batches(c))),
      to_writer(power_of_two_at_least(c.arenas.count + raw_batches(c) + 16)),
      status(4) {
  const std::size_t stride = arena_stride(c, points_per_frame);
  for (std::uint32_t i = 0; i < c.arenas.count; ++i) {
    std::uint8_t* const start = arena_memory.data() + i * stride;
    arenas.push_back(std::make_unique<FrameArena>(start, points_per_frame, pcd_format(c)));
    const std::size_t used = arenas.back()->frame.encoded.size();
    arena_memory.guard(start + used, stride - used);
    free_arenas.try_push(arenas.back().get());
  }
  for (std::uint32_t i = 0; i < raw_batches(c); ++i) {
    raw.push_back(std::make_unique<RawBatch>(c.arenas.packets_per_frame));
    free_raw.try_push(raw.back().get());
  }
} catch (const std::bad_alloc&) {
  throw std::runtime_error(fmt::format(
      "memory: the packet ring ({} slots x {} B, ring.slots) or the raw batches ({} x {} "
      "packets, arenas.count and arenas.packets_per_frame) do not fit: cannot allocate them",
      ring_slots, sizeof(PacketSlot), raw_batches(c), c.arenas.packets_per_frame));
}

void PipelineThreads::start(const char* name, std::function<void()> setup,
                            std::function<void()> body, std::function<void()> stop) {
  // Room first: a vector that failed to grow after the thread started would join it unasked.
  started_.reserve(started_.size() + 1);
  std::latch placed(1);
  try {
    started_.push_back(
        Started{std::move(stop),
                std::jthread([name, &placed, setup = std::move(setup), body = std::move(body)] {
                  pthread_setname_np(pthread_self(), name);
                  if (setup) setup();
                  placed.count_down();  // `placed` is not touched after this: start() returns
                  body();
                })});
  } catch (const std::system_error& error) {
    // No thread: a stack or thread limit (ulimit -s / -u, systemd's LimitSTACK=, TasksMax=).
    throw std::system_error(error.code(), fmt::format("cannot start thread {}", name));
  }
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
