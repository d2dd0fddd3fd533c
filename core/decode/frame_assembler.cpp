#include "core/decode/frame_assembler.hpp"

#include <algorithm>
#include <cmath>

#include "core/floor_div.hpp"
#include "core/sensors/sensor_model.hpp"
#include "core/sensors/timing.hpp"

namespace pandarcap {

namespace {

constexpr std::int64_t kFullCircle = 36000;
// An azimuth step larger than this between consecutive blocks is not rotation but a
// discontinuity (long loss, a restarted sensor, a foreign stream).
constexpr int kMaxStepCdeg = 9000;

// a - b on the circle, in [-18000, 18000).
int signed_step(int a, int b) {
  int d = (a - b) % 36000;
  if (d < -18000) d += 36000;
  if (d >= 18000) d -= 36000;
  return d;
}

}  // namespace

FrameAssembler::FrameAssembler(const FrameAssemblerConfig& config, FrameSink& sink)
    : config_(config),
      sink_(sink),
      channel_span_cdeg_(config.relative_azimuth_max_cdeg - config.relative_azimuth_min_cdeg) {
  double cut = std::fmod(config.cut_angle_deg, 360.0);
  if (cut < 0) cut += 360.0;
  cut_cdeg_ = static_cast<int>(std::lround(cut * 100)) % 36000;
}

void FrameAssembler::start_stream(std::uint16_t azimuth_cdeg) {
  started_ = true;
  position_ = (azimuth_cdeg - cut_cdeg_ + kFullCircle) % kFullCircle;
  start_position_ = position_;
  reach_position_ = position_;
  coverage_.reset(position_);
  next_open_index_ = floor_div(position_ + config_.relative_azimuth_min_cdeg, kFullCircle);
}

void FrameAssembler::add_packet(const PacketMeta& meta, std::span<const Point> points,
                                const DecodedPacket& layout) {
  ++packet_counter_;
  // More than half a revolution without packets: whole revolutions may be missing, which the
  // azimuth alone cannot tell. (What was lost is not counted from the time: a clock that steps
  // looks the same. The UDP sequence counts it, or the azimuth frames lacked.)
  const bool timed =
      packet_counter_ > 1 && meta.time_valid && previous_time_valid_ && meta.motor_rpm > 0;
  const std::int64_t gap_ns = meta.t0_ns - previous_t0_ns_;
  if (timed && started_) {
    const std::int64_t half_revolution_ns = 30'000'000'000LL / meta.motor_rpm;
    if (gap_ns > half_revolution_ns || gap_ns < -half_revolution_ns) discontinuity();
  }
  if (started_) {
    // A frame never spans more than a revolution of packets (frame_packet_limit: the channels'
    // reach past its ends and two packets for reordering), counted in packets, the sensor's own
    // firing clock (a clock that glitches does not stretch it): a motor that slowed, or turns
    // back and forth, must not pile packets into one frame. The revolution is the slowest the
    // frame's packets said (a speed change inside it), at the speeds a sensor runs at (a tail of
    // 0 or garbage says nothing).
    for (const Slot& slot : slots_) {
      if (!slot.in_use) continue;
      const double rpm =
          std::clamp<double>(std::min(slot.slowest_rpm, meta.motor_rpm), kSlowestRpm, kFastestRpm);
      if (slot.packets + 1 >
          frame_packet_limit_at(meta.packets_per_second, rpm, channel_span_cdeg_)) {
        ++stats_.frames_overlong;
        discontinuity();
        break;
      }
    }
  }
  previous_t0_ns_ = meta.t0_ns;
  previous_time_valid_ = meta.time_valid;
  // One block's firing turns the azimuth by this much: the packet's own span over its rounds.
  const int rounds = meta.firings;
  const int span =
      signed_step(meta.block_azimuth_cdeg[meta.block_count - 1], meta.block_azimuth_cdeg[0]);
  if (rounds > 1 && span > 0 && span < kMaxStepCdeg) {
    block_step_cdeg_ = static_cast<double>(span) / (rounds - 1);
    packet_step_cdeg_ = block_step_cdeg_ * rounds;
  } else if (rounds == 1 && meta.motor_rpm > 0 && meta.packets_per_second > 0) {
    // One firing a packet (a QT128 in dual return): no span to measure; the tail's speed says
    // how far a packet turns.
    const double rpm = std::clamp<double>(meta.motor_rpm, kSlowestRpm, kFastestRpm);
    packet_step_cdeg_ = rpm / 60.0 * kFullCircleCdeg / meta.packets_per_second;
    block_step_cdeg_ = packet_step_cdeg_;
  }
  const auto block_step = static_cast<std::int64_t>(std::lround(block_step_cdeg_));
  const std::int64_t margin = block_step / 2;  // the encoder's jitter, and rounding
  const std::int64_t previous_position = position_;
  const bool continued = started_;

  // Consecutive blocks bound for one frame go in with one add_points (one encoding call): the
  // run of them so far. Flushed before anything that may close or replace a frame.
  Run run;
  for (int b = 0; b < meta.block_count; ++b) {
    const std::uint16_t azimuth = meta.block_azimuth_cdeg[b];
    bool restarted = false;
    if (!started_) {
      start_stream(azimuth);
      restarted = true;
    } else {
      const int step = signed_step(azimuth, previous_azimuth_);
      if (std::abs(step) > kMaxStepCdeg) {
        ++stats_.discontinuities;
        add_run(run, points, meta);
        flush();
        start_stream(azimuth);
        restarted = true;
      } else {
        if (step < 0) ++stats_.azimuth_backward_steps;
        position_ += step;
      }
    }
    previous_azimuth_ = azimuth;
    // The block's firing covers its step of azimuth. Packets left out just before this one
    // leave the azimuth between uncovered but not lost, up to as many packets' worth as there
    // were.
    coverage_.advance(position_);
    coverage_.cover(position_ - margin, position_ + block_step + margin);
    if (b == 0 && continued && !restarted && meta.skipped_before > 0) {
      const std::int64_t from = previous_position + block_step;
      const double allowance = (meta.skipped_before + 0.5) * packet_step_cdeg_;
      if (position_ > from && static_cast<double>(position_ - from) <= allowance) {
        coverage_.leave_out(from, position_);
      }
    }
    reach_position_ = std::max(reach_position_, position_ + block_step);

    const std::size_t begin = layout.block_begin[b], end = layout.block_begin[b + 1];
    // Every point of the block lies within the channels' azimuth bounds of U: away from the cut
    // (all but a few blocks a revolution) they all fall in one frame, and go in together.
    const std::int64_t lowest =
        floor_div(position_ + config_.relative_azimuth_min_cdeg, kFullCircle);
    const std::int64_t highest =
        floor_div(position_ + config_.relative_azimuth_max_cdeg, kFullCircle);
    if (lowest == highest) {
      if (begin < end) {
        // The run goes on if this block continues it into the same frame, and all of it fits.
        const bool continues = run.slot != nullptr && run.slot->index == lowest &&
                               run.end == begin && fits(*run.slot, end - run.begin);
        if (!continues) add_run(run, points, meta);
        Slot* slot = continues ? run.slot : slot_for(lowest);
        if (slot == nullptr) {
          stats_.points_late += end - begin;
        } else if (continues) {
          run.end = end;
          run.lowest_position = std::min(run.lowest_position, position_);
          run.highest_position = std::max(run.highest_position, position_);
        } else {
          run = Run{slot, begin, end, position_, position_};
        }
      }
    } else {
      add_run(run, points, meta);
      for (std::size_t i = begin; i < end; ++i) {
        const Point& point = points[i];
        const std::int64_t u = position_ + signed_step(point.azimuth_cdeg, azimuth);
        Slot* slot = slot_for(floor_div(u, kFullCircle));
        if (slot == nullptr) {
          ++stats_.points_late;
        } else {
          add_points(*slot, std::span(&point, 1), meta, position_, position_);
        }
      }
    }

    // Frames that no channel can reach any more are done, a few packets later: a packet that
    // arrives a little late (reordered) still finds its frame open.
    const std::int64_t done =
        floor_div(position_ + config_.relative_azimuth_min_cdeg - kCloseMarginCdeg, kFullCircle);
    if (done > next_open_index_) {
      add_run(run, points, meta);
      close_through(done - 1, false);
    }
  }
  add_run(run, points, meta);
}

bool FrameAssembler::fits(const Slot& slot, std::size_t points) const {
  // A frame that is full or missing takes its points one block at a time, as they are counted.
  return !slot.dropped && points <= slot.frame->capacity() - slot.frame->size;
}

void FrameAssembler::add_run(Run& run, std::span<const Point> points, const PacketMeta& meta) {
  if (run.slot == nullptr) return;
  add_points(*run.slot, points.subspan(run.begin, run.end - run.begin), meta, run.lowest_position,
             run.highest_position);
  run = Run{};
}

FrameAssembler::Slot* FrameAssembler::slot_for(std::int64_t frame_index) {
  if (frame_index < next_open_index_) return nullptr;
  for (Slot& slot : slots_) {
    if (slot.in_use && slot.index == frame_index) return &slot;
  }
  // Only two frames can be open; a point beyond them means the older one is finished.
  if (frame_index >= next_open_index_ + 2) close_through(frame_index - 2, false);
  Slot* slot = slots_[0].in_use ? &slots_[1] : &slots_[0];
  *slot = Slot{};
  slot->in_use = true;
  slot->index = frame_index;
  slot->frame = sink_.acquire_frame();
  if (slot->frame == nullptr) {
    slot->dropped = true;
    ++stats_.frames_dropped;
  } else {
    slot->frame->reset();
  }
  return slot;
}

void FrameAssembler::add_points(Slot& slot, std::span<const Point> points, const PacketMeta& meta,
                                std::int64_t lowest_position, std::int64_t highest_position) {
  if (slot.counted_packet != packet_counter_) {
    slot.counted_packet = packet_counter_;
    ++slot.packets;
    slot.slowest_rpm = std::min(slot.slowest_rpm, meta.motor_rpm);
  }
  if (slot.dropped) {
    stats_.points_dropped_no_frame += points.size();
    return;
  }
  Frame& frame = *slot.frame;
  FrameInfo& info = frame.info;
  // Capacity first: a packet whose points were all dropped must not count towards the frame's
  // packets, RPM or time validity.
  const std::size_t room = frame.capacity() - frame.size;
  if (points.size() > room) {
    const std::size_t dropped = points.size() - room;
    stats_.points_dropped_full += dropped;
    info.points_dropped += static_cast<std::uint32_t>(dropped);
    points = points.first(room);
  }
  if (points.empty()) return;
  if (slot.last_packet != packet_counter_) {
    slot.last_packet = packet_counter_;
    slot.rpm_sum += meta.motor_rpm;
    ++info.packets;
    info.return_mode = meta.return_mode;
    info.time_valid = info.time_valid && meta.time_valid;
  }
  if (info.points == 0 || lowest_position < slot.first_position) {
    slot.first_position = lowest_position;
  }
  if (info.points == 0 || highest_position > slot.last_position) {
    slot.last_position = highest_position;
  }
  if (info.points == 0) {
    info.start_ns = info.end_ns = points.front().timestamp_ns;
    frame.reference_ns = points.front().timestamp_ns;
  }
  for (const Point& point : points) {
    info.start_ns = std::min(info.start_ns, point.timestamp_ns);
    info.end_ns = std::max(info.end_ns, point.timestamp_ns);
  }
  if (frame.is_encoded()) {
    const std::size_t step = pcd_point_bytes(frame.format.layout);
    encoder_.encode(points, frame.encoded.subspan(frame.size * step, points.size() * step),
                    frame.format, PcdFrameContext{frame.reference_ns, meta.return_mode});
  } else {
    std::copy(points.begin(), points.end(), frame.points.begin() + frame.size);
  }
  frame.size += points.size();
  info.points += static_cast<std::uint32_t>(points.size());
}

bool FrameAssembler::holed(const Slot& slot, bool whole_candidate) {
  // Half a packet's step: a lost packet leaves nearly a whole step uncovered, the encoder's
  // jitter and a small glitch placed where it was a fraction of one.
  const auto min_run = static_cast<std::int64_t>(packet_step_cdeg_ / 2);
  // Each packet covers its step and half a block's either side (add_packet): n lost packets
  // leave n steps less a block's step uncovered.
  const AzimuthCoverage::PacketSize size{packet_step_cdeg_, block_step_cdeg_};
  // What was lost inside this frame's own revolution, as far as the stream reached: counted
  // once, by the frame whose revolution holds it.
  const std::int64_t from = std::max(slot.index * kFullCircle, start_position_);
  const std::int64_t to = std::min((slot.index + 1) * kFullCircle, reach_position_);
  if (to > from) {
    stats_.packets_missing += coverage_.lost_packets(from, to, reach_position_, min_run, size);
  }
  if (!whole_candidate) return false;
  // Every azimuth a point of this frame can come from (the channels' offsets reach past its
  // revolution's ends), covered by a packet placed: one left out (an outlier that could not be
  // repaired) leaves it without that packet's points.
  const std::int64_t needed_from = slot.index * kFullCircle - config_.relative_azimuth_max_cdeg;
  const std::int64_t needed_to = (slot.index + 1) * kFullCircle - config_.relative_azimuth_min_cdeg;
  return coverage_.longest_uncovered_cdeg(needed_from, needed_to) >= min_run;
}

void FrameAssembler::close_slot(Slot& slot, bool partial) {
  // A frame is whole only if the stream had started before the frame began for every channel,
  // and lost no packet on the way.
  const bool started_late =
      slot.index * kFullCircle < start_position_ + config_.relative_azimuth_max_cdeg;
  const bool lost_packets = holed(slot, !partial && !started_late);
  if (lost_packets) ++stats_.frames_holed;
  // Numbered when finished, i.e. in revolution order; a dropped frame uses up its number too.
  const std::uint64_t sequence = frame_sequence_++;
  if (!slot.dropped) {
    FrameInfo& info = slot.frame->info;
    info.sequence = sequence;
    info.partial = partial || started_late || lost_packets;
    info.rpm = info.packets > 0 ? slot.rpm_sum / info.packets : 0;
    info.azimuth_span_cdeg = static_cast<std::uint32_t>(
        std::clamp<std::int64_t>(slot.last_position - slot.first_position, 0, kFullCircle));
    Frame& frame = *slot.frame;
    if (frame.is_encoded()) {
      // Encoded against the first point's time; an earlier one came later (reordered).
      if (info.points > 0 && info.start_ns < frame.reference_ns) {
        const auto bytes = frame.encoded.first(frame.size * pcd_point_bytes(frame.format.layout));
        rebase_pcd_times(bytes, frame.format.layout, frame.reference_ns - info.start_ns);
      }
      frame.reference_ns = info.start_ns;
    }
    ++(info.partial ? stats_.frames_partial : stats_.frames_complete);
    sink_.frame_done(*slot.frame);
  }
  slot = Slot{};
}

void FrameAssembler::close_through(std::int64_t frame_index, bool partial) {
  // Oldest first, so frames leave in the order they were started.
  Slot* order[2] = {&slots_[0], &slots_[1]};
  if (slots_[1].in_use && (!slots_[0].in_use || slots_[1].index < slots_[0].index)) {
    std::swap(order[0], order[1]);
  }
  for (Slot* slot : order) {
    if (slot->in_use && slot->index <= frame_index) close_slot(*slot, partial);
  }
  next_open_index_ = std::max(next_open_index_, frame_index + 1);
}

void FrameAssembler::discontinuity() {
  ++stats_.discontinuities;
  flush();
}

void FrameAssembler::flush() {
  if (started_) close_through(next_open_index_ + 2, true);
  started_ = false;
}

}  // namespace pandarcap
