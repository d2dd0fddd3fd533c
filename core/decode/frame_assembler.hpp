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
//  - discontinuities (an azimuth step of more than 90°, a packet-time gap of more than half a
//    revolution, a frame that would hold more than a revolution of packets at the tail's speed
//    (frame_packet_limit, core/sensors/sensor_model.hpp: the channels' reach and two packets for
//    reordering): a motor that slowed or turns back and forth; or the stream decoder's word, at
//    a change): the open frames are closed as partial and cutting restarts. A frame never holds
//    more than one revolution of azimuth, nor of the sensor's time (counted in packets, its
//    firing clock, which a glitching tail time does not stretch);
//  - completeness: a frame is complete only if its packets covered every azimuth its points can
//    come from (AzimuthCoverage): a lost packet leaves a run of azimuth uncovered at least half a
//    packet's step wide, and makes the frame partial, however few it lacks; so does a packet the
//    stream decoder left out (an outlier it could not repair: PacketMeta::skipped_before), whose
//    place is marked left out rather than lost. What was lost is counted in packets
//    (packets_missing): each uncovered run inside frames, not left out, over the packet's step.
//    Never from the time: a clock that steps, a glitch and a standing motor would look like lost
//    packets by it. A loss wider than 90° is a discontinuity, whose packets only the UDP sequence
//    counts (StreamDecoder::packets_missing());
//  - the first frame after start or a discontinuity is partial unless the stream started before
//    it began for every channel; frames open at flush() are partial;
//  - a small backward step (a reordered packet) moves U back. A frame is closed kCloseMarginCdeg
//    after the last point that can belong to it, so a packet a few late still finds it open;
//    points that fall into an already closed frame are counted as late and dropped.
// Pure state machine: no allocation (frames come from the FrameSink), no clocks, no I/O.
#pragma once

#include <cstdint>
#include <span>

#include "core/decode/azimuth_coverage.hpp"
#include "core/decode/decoder.hpp"
#include "core/decode/pcd_simd_encoder.hpp"
#include "core/frames/frame.hpp"
#include "core/sensors/packet.hpp"

namespace pandarcap {

struct FrameAssemblerConfig {
  double cut_angle_deg = 0.0;
  // (corrected azimuth - block azimuth) bounds over channels, from
  // ScalarDecoder::relative_azimuth_bounds_cdeg().
  int relative_azimuth_min_cdeg = -600;
  int relative_azimuth_max_cdeg = 400;
};

// What the assembler needs of a packet besides its points. Sized for the model with the most
// blocks (the 40P's 10); the model's stream decoder fills block_count of them and its rates.
struct PacketMeta {
  std::array<std::uint16_t, kBlocks> block_azimuth_cdeg{};
  int block_count = kBlocks;
  // Firings in this packet (blocks / returns per firing) and the model's packet rate in its
  // return mode: a revolution's packets at the tail's speed follow from them.
  int firings = kBlocks / 2;
  double packets_per_second = 3600;
  std::int64_t t0_ns = 0;
  bool time_valid = true;
  std::uint16_t motor_rpm = 0;
  ReturnMode return_mode = ReturnMode::kDual;
  // Packets received but left out just before this one (outliers that could not be repaired):
  // the azimuth they leave uncovered is theirs, not a loss (the frame is still partial).
  std::uint32_t skipped_before = 0;
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
  std::uint64_t frames_holed = 0;     // partial because a packet's azimuth was missing
  std::uint64_t frames_overlong = 0;  // cut at a revolution of packets (also discontinuities)
  std::uint64_t packets_missing = 0;  // estimated from the azimuth (see above)
};

class FrameAssembler {
 public:
  // How far past a frame's last possible point the rotation goes before the frame is closed:
  // 6°, 6 packets of a dual-return stream at 600 RPM, 1.5 of a single-return one at 1200.
  static constexpr std::int64_t kCloseMarginCdeg = 600;

  FrameAssembler(const FrameAssemblerConfig& config, FrameSink& sink);

  // Adds one decoded packet: its points (grouped by block as `layout` says) and metadata.
  void add_packet(const PacketMeta& meta, std::span<const Point> points,
                  const DecodedPacket& layout);
  // Closes the open frames as partial and forgets the rotation: the next packet starts a new
  // stream (end of input, shutdown, a long silence).
  void flush();
  // The same, counted as a discontinuity: the caller saw the stream change.
  void discontinuity();

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
    // Packets that gave it points (a dropped frame's too), and the slowest tail speed of them.
    std::uint64_t counted_packet = ~0ULL;
    std::uint32_t packets = 0;
    std::uint16_t slowest_rpm = 0xFFFF;
  };

  void start_stream(std::uint16_t azimuth_cdeg);
  // Whether `slot`'s frame lacks azimuth (a lost packet); counts what it lacks.
  bool holed(const Slot& slot, bool whole_candidate);
  Slot* slot_for(std::int64_t frame_index);
  void close_slot(Slot& slot, bool partial);
  void close_through(std::int64_t frame_index, bool partial);
  // Blocks of a packet, in order, whose points all go to one frame: points[begin, end), from
  // blocks at these positions (U).
  struct Run {
    Slot* slot = nullptr;
    std::size_t begin = 0, end = 0;
    std::int64_t lowest_position = 0, highest_position = 0;
  };
  // Whether `points` more fit in `slot`'s frame (one run never straddles a full frame).
  bool fits(const Slot& slot, std::size_t points) const;
  // Adds the run's points, if any, and empties it.
  void add_run(Run& run, std::span<const Point> points, const PacketMeta& meta);
  // Points from blocks at lowest..highest_position that all belong to `slot`'s frame (as many as
  // it has room for).
  void add_points(Slot& slot, std::span<const Point> points, const PacketMeta& meta,
                  std::int64_t lowest_position, std::int64_t highest_position);

  FrameAssemblerConfig config_;
  FrameSink& sink_;
  PcdEncoder encoder_;  // points into an encoded frame's arena: the fastest target this CPU runs
  int channel_span_cdeg_ = 0;  // how far the channels' azimuths reach past a block's, in all
  int cut_cdeg_ = 0;
  bool started_ = false;
  std::int64_t position_ = 0;        // U: unwrapped block azimuth relative to the cut, 0.01°
  std::int64_t start_position_ = 0;  // U when the stream (re)started
  std::uint16_t previous_azimuth_ = 0;
  std::int64_t previous_t0_ns_ = 0;
  bool previous_time_valid_ = false;
  // Coverage: the azimuth one block's firing spans (the last packet's, 0.01°), a packet's, and
  // how far the stream reached since it (re)started.
  AzimuthCoverage coverage_;
  double block_step_cdeg_ = 20;
  double packet_step_cdeg_ = 100;
  std::int64_t reach_position_ = 0;
  std::int64_t next_open_index_ = 0;  // frames below this index are closed
  std::uint64_t packet_counter_ = 0;
  std::uint64_t frame_sequence_ = 0;
  Slot slots_[2];
  AssemblerStats stats_;
};

}  // namespace pandarcap
