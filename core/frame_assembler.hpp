// Cuts the point stream into frames (revolutions) at cut_angle, per channel, by each point's
// corrected azimuth — so every channel's cloud ends exactly at the cut and no frame has the
// ~8° ragged seam that cutting per packet or per block leaves (channel azimuth offsets span
// -5.2°..+3.1°).
//
// How: the block azimuth is unwrapped relative to the cut into a running position U (0.01°,
// growing by the signed azimuth step between blocks). A point lies at U + (its corrected azimuth
// - its block azimuth), and belongs to frame floor(that / 36000). Two frames can be open at
// once, because near the cut some channels have crossed and others have not. Frame f is closed
// when U + (the most negative channel offset) has passed (f+1) x 360°: no later point can fall
// in it.
//
// Robustness:
//  - packet loss: U advances by the real azimuth step, so losing packets around the cut still
//    puts every point in the right frame;
//  - discontinuities (an azimuth step of more than 90°, or a packet-time gap of more than half a
//    revolution): the open frames are closed as partial and cutting restarts;
//  - the first frame after start or a discontinuity is partial unless the stream started before
//    it began for every channel; frames open at flush() are partial;
//  - a small backward step (a reordered packet) moves U back; points that fall into an already
//    closed frame are counted as late and dropped.
// Pure state machine: no allocation (frames come from the FrameSink), no clocks, no I/O.
#pragma once

#include <cstdint>
#include <span>

#include "decoder.hpp"
#include "frame.hpp"
#include "packet.hpp"

namespace pandarcap {

struct FrameAssemblerConfig {
  double cut_angle_deg = 0.0;
  // (corrected azimuth - block azimuth) bounds over channels, from
  // ScalarDecoder::relative_azimuth_bounds_cdeg().
  int relative_azimuth_min_cdeg = -600;
  int relative_azimuth_max_cdeg = 400;
};

// What the assembler needs of a packet besides its points.
struct PacketMeta {
  std::array<std::uint16_t, kBlocks> block_azimuth_cdeg{};
  std::int64_t t0_ns = 0;
  bool time_valid = true;
  std::uint16_t motor_rpm = 0;
  ReturnMode return_mode = ReturnMode::kDual;
};

struct AssemblerStats {
  std::uint64_t frames_complete = 0;
  std::uint64_t frames_partial = 0;
  std::uint64_t frames_dropped = 0;  // no free frame in the sink
  std::uint64_t points_dropped_no_frame = 0;
  std::uint64_t points_dropped_full = 0;  // frame capacity exceeded
  std::uint64_t points_late = 0;          // fell into an already closed frame
  std::uint64_t discontinuities = 0;
  std::uint64_t azimuth_backward_steps = 0;
};

class FrameAssembler {
 public:
  FrameAssembler(const FrameAssemblerConfig& config, FrameSink& sink);

  // Adds one decoded packet: its points (grouped by block as `layout` says) and metadata.
  void add_packet(const PacketMeta& meta, std::span<const Point> points,
                  const DecodedPacket& layout);
  // Closes the open frames as partial and forgets the rotation: the next packet starts a new
  // stream (end of input, shutdown, a long silence).
  void flush();

  const AssemblerStats& stats() const noexcept { return stats_; }

 private:
  struct Slot {
    std::int64_t index = 0;  // frame number relative to the stream start
    Frame* frame = nullptr;
    bool dropped = false;  // no frame could be had: its points are counted, not stored
    bool in_use = false;
    std::uint64_t last_packet = ~0ULL;
    double rpm_sum = 0;
    std::int64_t first_position = 0;  // U of the first and last block that added a point
    std::int64_t last_position = 0;
  };

  void start_stream(std::uint16_t azimuth_cdeg);
  Slot* slot_for(std::int64_t frame_index);
  void close_slot(Slot& slot, bool partial);
  void close_through(std::int64_t frame_index, bool partial);
  // Points of one block that all belong to `slot`'s frame (as many as it has room for).
  void add_points(Slot& slot, std::span<const Point> points, const PacketMeta& meta);

  FrameAssemblerConfig config_;
  FrameSink& sink_;
  int cut_cdeg_ = 0;
  bool started_ = false;
  std::int64_t position_ = 0;        // U: unwrapped block azimuth relative to the cut, 0.01°
  std::int64_t start_position_ = 0;  // U when the stream (re)started
  std::uint16_t previous_azimuth_ = 0;
  std::int64_t previous_t0_ns_ = 0;
  bool previous_time_valid_ = false;
  std::int64_t next_open_index_ = 0;  // frames below this index are closed
  std::uint64_t packet_counter_ = 0;
  std::uint64_t frame_sequence_ = 0;
  Slot slots_[2];
  AssemblerStats stats_;
};

}  // namespace pandarcap
