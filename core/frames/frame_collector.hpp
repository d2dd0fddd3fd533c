// A FrameSink for tools and tests: a fixed pool of frames allocated once, each handed back to
// the pool as soon as the callback has seen it. (The daemon's sink passes frames to its writer
// thread instead.)
#pragma once

#include <functional>
#include <vector>

#include "core/frames/frame.hpp"

namespace pandarcap {

class FrameCollector : public FrameSink {
 public:
  using Callback = std::function<void(const Frame&)>;

  // `frames` frames of `capacity_points` each, allocated here and never again.
  FrameCollector(std::size_t frames, std::size_t capacity_points, Callback callback)
      : storage_(frames * capacity_points), frames_(frames), callback_(std::move(callback)) {
    free_.reserve(frames);
    for (std::size_t i = 0; i < frames; ++i) {
      frames_[i].points = std::span<Point>(storage_).subspan(i * capacity_points, capacity_points);
      free_.push_back(&frames_[i]);
    }
  }

  Frame* acquire_frame() override {
    if (free_.empty()) return nullptr;
    Frame* frame = free_.back();
    free_.pop_back();
    return frame;
  }

  void frame_done(Frame& frame) override {
    callback_(frame);
    free_.push_back(&frame);
  }

 private:
  std::vector<Point> storage_;
  std::vector<Frame> frames_;
  std::vector<Frame*> free_;
  Callback callback_;
};

}  // namespace pandarcap
