// A frame (one revolution of points) and the interface through which the frame assembler gets
// empty frames and hands back finished ones.
#pragma once

#include <cstdint>
#include <span>

#include "core/frames/pcd.hpp"
#include "core/frames/point.hpp"
#include "core/sensors/packet.hpp"

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

// Storage for one frame, owned by whoever provides frames, in one of two forms:
//  - `points`: each point as a Point (tests, tools that look at points);
//  - `encoded`: each point already in the output layout `format` (the daemon's arenas), so the
//    PCD writer and MCAP persist the bytes as they are: the points are encoded once, by the
//    decode thread, and never again. Relative times (the velodyne and autoware layouts) are
//    against `reference_ns`, which is info.start_ns once the frame is finished.
// The frame assembler fills whichever has capacity (`encoded` when it is not empty).
struct Frame {
  FrameInfo info;
  std::span<Point> points;          // capacity, as Points
  std::span<std::uint8_t> encoded;  // capacity, as bytes of `format`
  PcdFormat format;
  std::int64_t reference_ns = 0;
  std::size_t size = 0;  // points used

  bool is_encoded() const noexcept { return !encoded.empty(); }
  std::size_t capacity() const noexcept {
    return is_encoded() ? encoded.size() / pcd_point_bytes(format.layout) : points.size();
  }
  std::span<const Point> used() const noexcept { return points.first(is_encoded() ? 0 : size); }
  std::span<const std::uint8_t> used_bytes() const noexcept {
    return is_encoded() ? encoded.first(size * pcd_point_bytes(format.layout))
                        : std::span<const std::uint8_t>();
  }
  void reset() noexcept {
    info = FrameInfo{};
    reference_ns = 0;
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
