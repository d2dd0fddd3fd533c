#include "core/decode/stream_decoder.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <stdexcept>
#include <string>
#include <utility>

#include "core/sensors/model_access.hpp"
#include "core/sensors/model_detection.hpp"
#include "core/sensors/sensor_model.hpp"
#include "core/sensors/sensor_models.hpp"
#include "core/sensors/timing.hpp"

namespace pandarcap {

std::uint64_t StreamStats::rejected() const noexcept {
  std::uint64_t sum = 0;
  for (std::size_t i = 1; i < kRejectReasonCount; ++i)
    sum += rejects[i];
  return sum;
}

namespace {

template <class Decoder>
FrameAssemblerConfig assembler_config(const Decoder& decoder, double cut_angle_deg) {
  const auto [lo, hi] = decoder.relative_azimuth_bounds_cdeg();
  return {cut_angle_deg, lo, hi};
}

// A 64-bit fingerprint of a payload, 8 bytes at a time in four independent lanes (about 60 ns
// for 1262 bytes). Never 0, which marks an empty place in the window.
std::uint64_t fingerprint(std::span<const std::uint8_t> payload) noexcept {
  constexpr std::uint64_t kMultiplier = 0x9E3779B97F4A7C15ULL;
  // Four named lanes, not an array: an array lives on the stack, and its first vector load of
  // four scalar stores stalls (a store-forwarding failure) on every packet.
  std::uint64_t l0 = payload.size(), l1 = 0x243F6A8885A308D3ULL, l2 = 0x13198A2E03707344ULL,
                l3 = 0xA4093822299F31D0ULL;
  const auto mix = [](std::uint64_t lane, const std::uint8_t* at) noexcept {
    std::uint64_t word;
    std::memcpy(&word, at, 8);
    lane = (lane ^ word) * kMultiplier;
    return lane ^ (lane >> 29);
  };
  std::size_t i = 0;
  for (; i + 32 <= payload.size(); i += 32) {
    l0 = mix(l0, payload.data() + i);
    l1 = mix(l1, payload.data() + i + 8);
    l2 = mix(l2, payload.data() + i + 16);
    l3 = mix(l3, payload.data() + i + 24);
  }
  std::uint64_t* lanes[4] = {&l0, &l1, &l2, &l3};
  for (; i < payload.size(); ++i)
    *lanes[i % 4] = (*lanes[i % 4] ^ payload[i]) * kMultiplier;
  std::uint64_t h = l0 ^ (l1 * 3) ^ (l2 * 5) ^ (l3 * 7);
  h ^= h >> 31;
  return h == 0 ? 1 : h;
}

}  // namespace

template <class Model>
void BasicStreamDecoder<Model>::track_azimuth(std::uint16_t azimuth_cdeg, std::int64_t t0_ns,
                                              bool time_valid, std::uint16_t rpm, ReturnMode mode) {
  const std::optional<std::uint16_t> previous = previous_azimuth_cdeg_;
  previous_azimuth_cdeg_ = azimuth_cdeg;
  if (!previous || !previous_t0_ns_) return;
  const int step = (azimuth_cdeg - *previous + 36000) % 36000;  // forward, 0..35999
  const std::int64_t dt = t0_ns - *previous_t0_ns_;
  // Both from one clock: an invalid date still has a running microseconds field (a sensor
  // without a date), but a good time and a bad one are not comparable.
  const bool times_valid = time_valid == previous_time_valid_;
  // The step one packet should make at the reported speed (600 RPM dual: 100 cdeg).
  const int returns = returns_per_firing(mode);
  const double expected = Model::azimuth_step_per_packet_cdeg(returns, rpm);
  const bool gap = step > 1.5 * expected + 5;
  // Spin is measured over consecutive packets as they arrive (whether placed or not: a crawling
  // motor's packets may all be outliers): a loss, a glitch or a restart is not spin. A standing
  // motor's step is 0, and counts: it measures 0 RPM.
  const auto period = Model::packet_period_ns(returns);
  if (times_valid && !gap && dt > 0 && dt <= period + period / 2) {
    stats_.measured_azimuth_cdeg += static_cast<std::uint64_t>(step);
    stats_.measured_time_ns += static_cast<std::uint64_t>(dt);
  }
  // The packet rate by the sensor's clock (two merged streams: twice the packets).
  if (times_valid && dt >= 0 && dt <= 100'000'000) {
    ++stats_.rate_packets;
    stats_.rate_time_ns += static_cast<std::uint64_t>(dt);
  }
}

namespace {

const Calibration& checked(const Calibration& calibration, int channels) {
  if (calibration.channel_count != channels) {
    throw std::invalid_argument("the calibration has " + std::to_string(calibration.channel_count) +
                                " channels, the sensor model " + std::to_string(channels));
  }
  return calibration;
}

}  // namespace

template <class Model>
BasicStreamDecoder<Model>::BasicStreamDecoder(const Calibration& calibration,
                                              const StreamDecoderConfig& config, FrameSink& sink)
    : decoder_(checked(calibration, Model::kChannels), config.decoder, config.decoder_target),
      assembler_(assembler_config(decoder_, config.cut_angle_deg), sink),
      decode_points_(config.decode_points) {}

template <class Model>
bool BasicStreamDecoder<Model>::duplicate(std::span<const std::uint8_t> payload) noexcept {
  const std::uint64_t print = fingerprint(payload);
  for (const std::uint64_t recent : recent_) {
    if (recent == print) return true;
  }
  recent_[recent_next_] = print;
  recent_next_ = (recent_next_ + 1) % kDuplicateWindow;
  return false;
}

template <class Model>
RejectReason BasicStreamDecoder<Model>::process(std::span<const std::uint8_t> payload) {
  ++stats_.packets;
  RejectReason reason = Model::validate(payload);
  if (reason != RejectReason::kNone) {
    // Another model's packet is its own reason, whatever this model's check tripped on (a 64's
    // packet is no 40P length): a second sensor, or the wrong --sensor-model.
    const DetectedModel other = identify_model(payload);
    if (other.kind == DetectionKind::kKnown && other.model != Model::kId) {
      reason = RejectReason::kWrongModel;
    } else if (other.kind == DetectionKind::kUnsupported) {
      reason = RejectReason::kUnsupportedModel;
    }
  }
  ++stats_.rejects[static_cast<std::size_t>(reason)];
  if (reason != RejectReason::kNone) return reason;
  // A burst's return mode (see other_mode_run_): up to kMaxHeldPackets in a row that say another
  // mode than the stream's are a glitch of that byte, decoded in the stream's mode (the blocks
  // are laid out alike) and counted as outliers; the next one is a change of mode, taken.
  bool mode_repaired = false;
  if (const ReturnMode said = Model::return_mode(payload); stream_mode_ && said != *stream_mode_) {
    other_mode_run_ = other_mode_run_ > 0 && said == other_mode_ ? other_mode_run_ + 1 : 1;
    other_mode_ = said;
    if (other_mode_run_ <= kMaxHeldPackets) {
      std::memcpy(repaired_.data(), payload.data(), payload.size());
      repaired_[return_mode_offset<Model>(payload)] = static_cast<std::uint8_t>(*stream_mode_);
      payload = std::span<const std::uint8_t>(repaired_).first(payload.size());
      mode_repaired = true;
    }
  } else {
    other_mode_run_ = 0;
  }
  // A copy is counted once, and nothing of it is decoded again or counted as the stream's.
  if (duplicate(payload)) {
    ++stats_.duplicates;
    return RejectReason::kNone;
  }
  const ReturnMode mode = Model::return_mode(payload);
  const std::int64_t period = Model::packet_period_ns(returns_per_firing(mode));
  const TailDateTime utc = tail_datetime<Model>(payload);
  const std::uint32_t timestamp_us = Model::timestamp_us(payload);
  const PacketTime time = clock_.convert(utc, timestamp_us);
  const std::optional<std::uint32_t> sequence_number = Model::sequence(payload);
  if (const auto sequence = sequence_number) {
    // The packet's time tells a late copy (as old as its number says) from a sensor that
    // restarted its counter (a number already seen, at a new time).
    std::optional<SequenceClock> clock;
    if (time.valid()) clock = SequenceClock{time.t0_ns, period};
    if (sequence_.observe(*sequence, clock) == SequenceTracker::Verdict::kDuplicate) {
      ++stats_.duplicates;
      return RejectReason::kNone;
    }
    ++stats_.sequence_packets;
  }
  ++stats_.accepted;

  const std::uint16_t tail_rpm = Model::motor_rpm(payload);
  stats_.rpm_min = stats_.accepted == 1 ? tail_rpm : std::min(stats_.rpm_min, tail_rpm);
  stats_.rpm_max = stats_.accepted == 1 ? tail_rpm : std::max(stats_.rpm_max, tail_rpm);
  // One packet's tail speed is not the stream's (see stream_rpm_): a real change is taken at
  // its second packet.
  if (!stream_rpm_ || tail_rpm == previous_tail_rpm_) stream_rpm_ = tail_rpm;
  previous_tail_rpm_ = tail_rpm;
  const std::uint16_t rpm = *stream_rpm_;
  if (mode_repaired) ++stats_.outliers;
  if (stream_mode_ && *stream_mode_ != mode) ++stats_.return_mode_changes;
  stream_mode_ = mode;
  stats_.return_mode = mode;
  const bool high_temperature = Model::high_temperature(payload);
  if (high_temperature) ++stats_.high_temperature;
  const bool sequence_present = sequence_number.has_value();

  if (!time.valid()) {
    ++(time.status == PacketTimeStatus::kBadDate ? stats_.bad_date : stats_.bad_microseconds);
    const InvalidTimeField bad = first_invalid_field(utc, timestamp_us);
    stats_.last_invalid_field = bad.field;
    stats_.last_invalid_value = bad.value;
  }
  // A clock that froze is counted as the packets arrive. One that went back or leapt is judged
  // against the stream by the outlier rule, so the packet that returns to the stream after a
  // glitch is not taken for a step of its own.
  if (previous_t0_ns_ && time.t0_ns == *previous_t0_ns_) ++stats_.static_timestamps;
  const std::uint16_t azimuth = Model::azimuth_cdeg(payload, 0);
  // Against the last packet placed and the packet before: the packet that returns to the stream
  // after a glitch of shifted (or zeroed) azimuths is no standing motor, nor is a burst of equal
  // azimuths, nor a shifted packet that happens to land on the last one placed.
  bool standing =
      last_placed_ && previous_azimuth_cdeg_ &&
      std::abs(signed_step_cdeg(azimuth, last_placed_->azimuth_cdeg)) <= kStandingStepCdeg &&
      std::abs(signed_step_cdeg(azimuth, *previous_azimuth_cdeg_)) <= kStandingStepCdeg;
  const RotationPoint rotation{azimuth, time.t0_ns, time.valid(), rpm};
  if (standing && !stood_) {
    // The first packet that stands may be a glitch that put it on the last one placed (shifted
    // back a packet's step): held like any that does not follow, and repaired if the stream goes
    // on. The next that stands too says the motor stopped: the held one stood as well.
    if (held_.size() == 1 && std::abs(signed_step_cdeg(held_.newest().rotation.azimuth_cdeg,
                                                       azimuth)) <= kStandingStepCdeg) {
      held_.clear();
      ++stats_.standing;
      filter_packet(FilterReason::kStanding);
    } else if (!follows(*last_placed_, rotation, turning_)) {
      standing = false;  // (Without usable times, the azimuth alone says it stood.)
    }
  }
  stood_ = standing;
  track_azimuth(azimuth, time.t0_ns, time.valid(), rpm, mode);
  previous_t0_ns_ = time.t0_ns;
  previous_time_valid_ = time.valid();
  stats_.last_t0_ns = time.t0_ns;
  stats_.last_time_valid = time.status == PacketTimeStatus::kValid;
  stats_.last_rpm = rpm;
  stats_.last_high_temperature = high_temperature;
  sequence_present_ = sequence_present;

  if (standing) {
    // The motor did not turn: counted, never placed (see the top of the header).
    ++stats_.standing;
    filter_packet(FilterReason::kStanding);
  } else {
    place_or_hold(payload, AdmittedPacket{rotation, time, period, stats_.accepted});
  }
  // A stream turning backwards closes no frame by design (its packets are counted as reversed).
  if (turning_ == Turning::kForward) {
    watch_frames(rpm, mode);
  } else {
    packets_since_frame_ = 0;
  }
  return RejectReason::kNone;
}

template <class Model>
void BasicStreamDecoder<Model>::place_or_hold(std::span<const std::uint8_t> payload,
                                              const AdmittedPacket& admitted) {
  const bool follows_stream = last_placed_ && follows(*last_placed_, admitted.rotation, turning_);
  if (held_.empty()) {
    if (follows_stream) {
      place(payload, admitted);
    } else {
      held_.push(payload, admitted, std::nullopt);
    }
    return;
  }
  if (follows_stream) {
    // The stream went on as if the held run had not been there: a glitch.
    settle_outliers(admitted.rotation);
    place(payload, admitted);
    return;
  }
  // The held run's newest is always the chain's newest. A chain turns one way: the first two
  // packets say which.
  const RotationPoint& newest = held_.newest().rotation;
  const std::optional<Turning> turning = held_.chain_turning();
  std::optional<Turning> extends;
  if (turning != Turning::kBackward && follows(newest, admitted.rotation, Turning::kForward)) {
    extends = Turning::kForward;
  } else if (turning != Turning::kForward &&
             follows(newest, admitted.rotation, Turning::kBackward)) {
    extends = Turning::kBackward;
  }
  if (extends && held_.chain_length() + 1 >= kChangeRunPackets) {
    take_change(true);  // 17 packets that follow each other and not the stream: it changed
    place(payload, admitted);
    return;
  }
  // Full: the oldest is a stray (a full chain would have made 17 with this one).
  if (held_.full()) drop_oldest_as_outlier();
  held_.push(payload, admitted, extends);
}

namespace {

// An outlier's time against the stream it interrupted: behind the packet before it went back,
// ahead of the packet after it leapt forward.
void count_outlier_time(const PacketTime& time, const RotationPoint& before,
                        const RotationPoint& after, StreamStats& stats) noexcept {
  if (!time.valid() || !before.time_valid) return;
  if (time.t0_ns < before.t0_ns) {
    ++stats.backward_timestamps;
  } else if (after.time_valid && time.t0_ns > after.t0_ns) {
    ++stats.timestamp_jumps;
  }
}

}  // namespace

template <class Model>
void BasicStreamDecoder<Model>::settle_outliers(const RotationPoint& after) {
  const RotationPoint before = *last_placed_;
  if (turning_ == Turning::kBackward) {
    // Nothing of a backwards stream is placed: its glitches are outliers, left out.
    for (std::size_t i = 0; i < held_.size(); ++i) {
      ++stats_.outliers;
      count_outlier_time(held_.admitted(i).time, before, after, stats_);
      filter_packet(FilterReason::kOutlier);
    }
    held_.clear();
    return;
  }
  const int to_after = signed_step_cdeg(after.azimuth_cdeg, before.azimuth_cdeg);
  const std::int64_t dt = after.t0_ns - before.t0_ns;
  // (Within a second: a stream without a speed follows by azimuth alone, whatever its times
  // say, and the interpolation below must not overflow.)
  const bool timed =
      to_after > 0 && dt > 0 && dt <= kTimestampJumpNs && before.time_valid && after.time_valid;
  // The run's places: held packet i is the (forgotten + i + 1)-th packet after `before`, and
  // `after` the (sent)-th. When the time says exactly these were sent (none lost among them),
  // each has its place: a fraction of the way in time and in azimuth. Else only the order is
  // known: between the neighbours, after the one placed before it.
  const auto sent = static_cast<std::int64_t>(held_.forgotten() + held_.size() + 1);
  const std::int64_t period = held_.admitted(0).period_ns;
  const bool places_known = timed && period > 0 && std::llabs(dt - sent * period) < period / 2;
  // The rotation's step a packet between the neighbours (a repaired azimuth's blocks follow it).
  const double packet_step = static_cast<double>(to_after) * static_cast<double>(period) /
                             static_cast<double>(std::max<std::int64_t>(dt, 1));
  int placed_to = 0;  // azimuth of the last one placed, from `before`: they stay in order
  std::int64_t placed_t0 = before.t0_ns;
  for (std::size_t i = 0; i < held_.size(); ++i) {
    ++stats_.outliers;
    const AdmittedPacket& held = held_.admitted(i);
    count_outlier_time(held.time, before, after, stats_);
    const int to_held = signed_step_cdeg(held.rotation.azimuth_cdeg, before.azimuth_cdeg);
    const std::int64_t t_held = held.time.t0_ns;
    bool time_right = false, azimuth_right = false;
    if (places_known) {
      const auto place = static_cast<std::int64_t>(held_.forgotten() + i + 1);
      const std::int64_t t_place = before.t0_ns + dt * place / sent;
      const double at_place =
          static_cast<double>(to_after) * static_cast<double>(place) / static_cast<double>(sent);
      time_right = held.time.valid() && std::llabs(t_held - t_place) < period / 2;
      azimuth_right = std::abs(to_held - at_place) <= follow_tolerance_cdeg(at_place);
    } else if (timed) {
      time_right = held.time.valid() && t_held > placed_t0 && t_held < after.t0_ns;
      azimuth_right = to_held >= placed_to && to_held <= to_after;
    }
    if (time_right) {
      // Its time is its place: its azimuth is where the rotation was then (a shifted azimuth, or
      // the packet's own within the jitter).
      const auto at = static_cast<int>(to_after * (t_held - before.t0_ns) / dt);
      const int shift = at - to_held;
      place_repaired(i, before, std::abs(shift) <= kFollowJitterCdeg ? to_held : at, t_held,
                     packet_step);
      placed_to = std::abs(shift) <= kFollowJitterCdeg ? to_held : at;
      placed_t0 = t_held;
    } else if (azimuth_right) {
      // Its azimuth is its place: only its time was wrong (back, forward, a second off, zeroed).
      // Placed at the time the rotation gives that azimuth, its points kept.
      const std::int64_t t_fixed = before.t0_ns + dt * to_held / to_after;
      place_repaired(i, before, to_held, t_fixed, packet_step);
      placed_to = to_held;
      placed_t0 = t_fixed;
    } else {
      // Neither: left out, its slots counted; the frame it belonged to is partial, and told a
      // packet was left out there (not lost).
      filter_packet(FilterReason::kOutlier);
      ++skipped_;
    }
  }
  held_.clear();
}

template <class Model>
void BasicStreamDecoder<Model>::place_repaired(std::size_t i, const RotationPoint& before,
                                               int at_cdeg, std::int64_t t0_ns,
                                               double packet_step_cdeg) {
  AdmittedPacket fixed = held_.admitted(i);
  const int target = (before.azimuth_cdeg + at_cdeg % 36000 + 36000) % 36000;
  if (target != fixed.rotation.azimuth_cdeg) {
    held_.template move_azimuth<Model>(i, target, packet_step_cdeg);
    fixed.rotation.azimuth_cdeg = held_.admitted(i).rotation.azimuth_cdeg;
  }
  fixed.time.t0_ns = t0_ns;
  fixed.time.status = PacketTimeStatus::kValid;
  fixed.rotation.t0_ns = t0_ns;
  fixed.rotation.time_valid = true;
  place(held_.bytes(i), fixed);
}

template <class Model>
void BasicStreamDecoder<Model>::take_change(bool counted) {
  const std::size_t start = held_.chain_start();
  for (std::size_t i = 0; i < start; ++i) {
    ++stats_.outliers;
    filter_packet(FilterReason::kOutlier);
  }
  const AdmittedPacket& first = held_.admitted(start);
  if (counted && last_placed_) {
    ++stats_.stream_changes;
    if (last_placed_->time_valid && first.time.valid()) {
      // The clock of the new stream against the old one's: back, or on while the azimuth went
      // on as if only the packets in between had passed (a clock that leapt, not a gap).
      const std::int64_t dt = first.time.t0_ns - last_placed_->t0_ns;
      // (Every packet that arrived in between: strays, outliers, a standing motor's.)
      const auto between = static_cast<double>(first.arrival - placed_arrival_);
      const double step =
          last_placed_->rpm / 60.0 * kFullCircleCdeg * static_cast<double>(first.period_ns) * 1e-9;
      const int moved = signed_step_cdeg(first.rotation.azimuth_cdeg, last_placed_->azimuth_cdeg);
      const double expected = static_cast<int>(turning_) * step * between;
      const bool azimuth_went_on = std::abs(moved - expected) <= follow_tolerance_cdeg(expected);
      if (dt < 0) {
        ++stats_.backward_timestamps;
      } else if (azimuth_went_on &&
                 static_cast<double>(dt) > static_cast<double>(first.period_ns) * (between + 0.5)) {
        ++stats_.timestamp_jumps;
      }
    }
  }
  // The frames in progress end where the stream changed: its rotation (or its clock) is not the
  // one they were cut by.
  if (counted && decode_points_ && last_placed_) assembler_.discontinuity();
  if (held_.chain_turning()) turning_ = *held_.chain_turning();
  // Whatever was left out belonged to the old stream.
  skipped_ = 0;
  for (std::size_t i = start; i < held_.size(); ++i)
    place(held_.bytes(i), held_.admitted(i));
  held_.clear();
}

template <class Model>
void BasicStreamDecoder<Model>::drop_oldest_as_outlier() noexcept {
  ++stats_.outliers;
  filter_packet(FilterReason::kOutlier);
  ++skipped_;
  held_.pop_oldest();
}

template <class Model>
void BasicStreamDecoder<Model>::filter_packet(FilterReason reason) noexcept {
  stats_.filtered.add(reason, std::uint64_t{Model::kBlocks} * Model::kChannels);
}

template <class Model>
void BasicStreamDecoder<Model>::watch_frames(std::uint16_t rpm, ReturnMode mode) noexcept {
  if (!decode_points_) return;
  const AssemblerStats& f = assembler_.stats();
  const std::uint64_t closed = f.frames_complete + f.frames_partial + f.frames_dropped;
  if (closed != frames_closed_) {
    frames_closed_ = closed;
    packets_since_frame_ = 0;
    return;
  }
  // Three revolutions at the tail's speed (kept to the speeds a sensor runs at: a tail of 0 or
  // of garbage says nothing of how long a revolution is).
  const double speed = std::clamp<double>(rpm, kSlowestRpm, kFastestRpm);
  if (static_cast<double>(++packets_since_frame_) >
      3 * Model::packets_per_revolution(returns_per_firing(mode), speed)) {
    ++stats_.frameless_packets;
  }
}

template <class Model>
void BasicStreamDecoder<Model>::place(std::span<const std::uint8_t> payload,
                                      const AdmittedPacket& admitted) {
  const std::optional<RotationPoint> previous = last_placed_;
  last_placed_ = admitted.rotation;
  placed_arrival_ = admitted.arrival;
  last_placed_->time_stood = previous && previous->time_valid && admitted.rotation.time_valid &&
                             previous->t0_ns == admitted.rotation.t0_ns;
  const std::uint32_t skipped = std::exchange(skipped_, 0);
  if (turning_ == Turning::kBackward) {
    // A stream turning backwards: counted and left out, never cut into frames.
    ++stats_.reversed;
    filter_packet(FilterReason::kReversed);
    return;
  }
  const ReturnMode mode = Model::return_mode(payload);
  const int returns = returns_per_firing(mode);
  // Without a UDP sequence, a loss shows as a step between packets placed wider than the tail's
  // speed allows (the packets left out between them aside).
  if (previous && !sequence_present_) {
    const int step = (admitted.rotation.azimuth_cdeg - previous->azimuth_cdeg + 36000) % 36000;
    const double expected = Model::azimuth_step_per_packet_cdeg(returns, admitted.rotation.rpm);
    if (step > (1.5 + skipped) * expected + 5 && step < 18000) ++stats_.azimuth_gaps;
  }
  if (!decode_points_) return;  // the health needs only where the rotation is
  const DecodedPacket decoded =
      decoder_.decode(payload, admitted.time.t0_ns, points_, stats_.filtered);
  stats_.points += decoded.point_count;

  PacketMeta meta;
  for (int b = 0; b < Model::kBlocks; ++b)
    meta.block_azimuth_cdeg[b] = Model::azimuth_cdeg(payload, b);
  meta.block_count = Model::kBlocks;
  meta.firings = Model::firings_per_packet(returns);
  meta.packets_per_second = Model::packets_per_second(returns);
  meta.t0_ns = admitted.time.t0_ns;
  meta.time_valid = admitted.time.valid();
  meta.motor_rpm = admitted.rotation.rpm;
  meta.return_mode = mode;
  meta.skipped_before = skipped;
  assembler_.add_packet(meta, std::span<const Point>(points_).first(decoded.point_count), decoded);
}

template <class Model>
void BasicStreamDecoder<Model>::flush() {
  // Nothing came after the held run to say it was a glitch: its chain is placed (a change at the
  // very end), the strays before it are outliers.
  if (!held_.empty()) take_change(false);
  assembler_.flush();
  last_placed_.reset();
  turning_ = Turning::kForward;
  stood_ = false;
  skipped_ = 0;
}

template class BasicStreamDecoder<Pandar40P>;
template class BasicStreamDecoder<Pandar64>;
template class BasicStreamDecoder<PandarXT32>;
template class BasicStreamDecoder<PandarXT16>;
template class BasicStreamDecoder<PandarQT128>;

}  // namespace pandarcap
