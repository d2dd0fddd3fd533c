// A frame (one revolution of points) and the interface through which the frame assembler gets
// empty frames and hands back finished ones.
#pragma once

#include <cstdint>
#include <span>

#include "packet.hpp"
#include "point.hpp"

namespace pandarcap {

// Points in the largest frame the sensor produces: 1800 firing rounds per revolution at 600 RPM
// x 40 channels x 2 returns, plus 25 % margin for slower spin and jitter.
inline constexpr std::size_t kDefaultFrameCapacityPoints = 1800 * 40 * 2 * 5 / 4;

struct FrameInfo {
  std::uint64_t sequence = 0;  // 0, 1, 2, ... in revolution order; a gap = a dropped frame
  std::int64_t start_ns = 0;   // earliest point time
  std::int64_t end_ns = 0;     // latest point time
  std::uint32_t points = 0;
  std::uint32_t packets = 0;                   // packets that contributed at least one point
  double rpm = 0;                              // mean of the tail motor speed over those packets
  ReturnMode return_mode = ReturnMode::kDual;  // of the last packet that contributed
  bool partial = false;              // did not see its whole revolution (first frame, loss, end)
  bool time_valid = true;            // every contributing packet had a valid absolute time
  std::uint32_t points_dropped = 0;  // points that did not fit (capacity)
  // How much of a revolution the frame's blocks cover (last minus first block azimuth, 0.01°):
  // ~36000 for a whole frame, less for a partial one. A partial frame below
  // output.frames_min_fraction of 36000 is a fragment, counted and not written.
  std::uint32_t azimuth_span_cdeg = 0;
};

// Storage for one frame. `points` is fixed-capacity storage owned by whoever provides frames.
struct Frame {
  FrameInfo info;
  std::span<Point> points;  // capacity
  std::size_t size = 0;     // points used

  std::span<const Point> used() const noexcept { return points.first(size); }
  void reset() noexcept {
    info = FrameInfo{};
    size = 0;
  }
};

// Provides empty frames and takes finished ones (the daemon's arena pool, a test's collector).
class FrameSink {
 public:
  virtual ~FrameSink() = default;
  // An empty frame to fill, or nullptr when none is free: the frame is then dropped and counted.
  virtual Frame* acquire_frame() = 0;
  // A finished frame (complete or partial), handed back to its owner.
  virtual void frame_done(Frame& frame) = 0;
};

}  // namespace pandarcap
