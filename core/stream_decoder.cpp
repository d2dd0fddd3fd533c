#include "stream_decoder.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>

#include "timing.hpp"

namespace pandarcap {

std::uint64_t StreamStats::rejected() const noexcept {
  std::uint64_t sum = 0;
  for (std::size_t i = 1; i < kRejectReasonCount; ++i)
    sum += rejects[i];
  return sum;
}

namespace {

FrameAssemblerConfig assembler_config(const ScalarDecoder& decoder, double cut_angle_deg) {
  const auto [lo, hi] = decoder.relative_azimuth_bounds_cdeg();
  return {cut_angle_deg, lo, hi};
}

// A 64-bit fingerprint of a payload, 8 bytes at a time in four independent lanes (about 60 ns
// for 1262 bytes). Never 0, which marks an empty place in the window.
std::uint64_t fingerprint(std::span<const std::uint8_t> payload) noexcept {
  constexpr std::uint64_t kMultiplier = 0x9E3779B97F4A7C15ULL;
  std::uint64_t lane[4] = {payload.size(), 0x243F6A8885A308D3ULL, 0x13198A2E03707344ULL,
                           0xA4093822299F31D0ULL};
  std::size_t i = 0;
  for (; i + 32 <= payload.size(); i += 32) {
    for (int k = 0; k < 4; ++k) {
      std::uint64_t word;
      std::memcpy(&word, payload.data() + i + 8 * k, 8);
      lane[k] = (lane[k] ^ word) * kMultiplier;
      lane[k] ^= lane[k] >> 29;
    }
  }
  for (; i < payload.size(); ++i)
    lane[i % 4] = (lane[i % 4] ^ payload[i]) * kMultiplier;
  std::uint64_t h = lane[0] ^ (lane[1] * 3) ^ (lane[2] * 5) ^ (lane[3] * 7);
  h ^= h >> 31;
  return h == 0 ? 1 : h;
}

// a - b on the circle, in [-18000, 18000).
int signed_step(int a, int b) noexcept {
  int d = (a - b) % 36000;
  if (d < -18000) d += 36000;
  if (d >= 18000) d -= 36000;
  return d;
}

}  // namespace

bool follows(const RotationPoint& last, const RotationPoint& next) noexcept {
  const int step = signed_step(next.azimuth_cdeg, last.azimuth_cdeg);
  const std::int64_t dt = next.t0_ns - last.t0_ns;
  if (!last.time_valid || !next.time_valid || dt == 0 || last.rpm == 0) {
    return std::abs(step) <= 9000;
  }
  // Half a revolution without packets is a gap whole revolutions may hide in (the assembler's
  // rule): never "follows".
  const double revolution_ns = 60e9 / last.rpm;
  if (std::abs(static_cast<double>(dt)) > revolution_ns / 2) return false;
  const double expected_cdeg = static_cast<double>(dt) / revolution_ns * 36000.0;
  return std::abs(step - expected_cdeg) <= 200.0 + 0.02 * std::abs(expected_cdeg);
}

void StreamDecoder::track_azimuth(std::uint16_t azimuth_cdeg, std::int64_t t0_ns, std::uint16_t rpm,
                                  ReturnMode mode, bool sequence_present) {
  const std::optional<std::uint16_t> previous = previous_azimuth_cdeg_;
  previous_azimuth_cdeg_ = azimuth_cdeg;
  if (!previous || !previous_t0_ns_) return;
  const int step = (azimuth_cdeg - *previous + 36000) % 36000;  // forward, 0..35999
  const std::int64_t dt = t0_ns - *previous_t0_ns_;
  // The step one packet should make at the reported speed (600 RPM dual: 100 cdeg).
  const double expected = rpm / 60.0 * 36000.0 * static_cast<double>(packet_period_ns(mode)) * 1e-9;
  const bool gap = step > 1.5 * expected + 5;
  if (gap && !sequence_present && step < 18000) ++stats_.azimuth_gaps;
  // A time gap over 100 ms or a big step is an outage or restart, not spin: leave it out.
  if (!gap && step > 0 && dt > 0 && dt < 100'000'000) {
    stats_.measured_azimuth_cdeg += static_cast<std::uint64_t>(step);
    stats_.measured_time_ns += static_cast<std::uint64_t>(dt);
  }
}

StreamDecoder::StreamDecoder(const Calibration& calibration, const StreamDecoderConfig& config,
                             FrameSink& sink)
    : decoder_(calibration, config.decoder, config.decoder_target),
      assembler_(assembler_config(decoder_.scalar(), config.cut_angle_deg), sink),
      decode_points_(config.decode_points) {}

bool StreamDecoder::duplicate(std::span<const std::uint8_t> payload) noexcept {
  const std::uint64_t print = fingerprint(payload);
  for (const std::uint64_t recent : recent_) {
    if (recent == print) return true;
  }
  recent_[recent_next_] = print;
  recent_next_ = (recent_next_ + 1) % kDuplicateWindow;
  return false;
}

RejectReason StreamDecoder::process(std::span<const std::uint8_t> payload) {
  ++stats_.packets;
  const RejectReason reason = validate(payload);
  ++stats_.rejects[static_cast<std::size_t>(reason)];
  if (reason != RejectReason::kNone) return reason;
  const PacketView packet = PacketView::assume_valid(payload);
  // A copy is counted once, and nothing of it is decoded again or counted as the stream's.
  if (duplicate(payload)) {
    ++stats_.duplicates;
    return RejectReason::kNone;
  }
  if (const auto sequence = packet.sequence()) {
    if (sequence_.observe(*sequence) == SequenceTracker::Verdict::kDuplicate) {
      ++stats_.duplicates;
      return RejectReason::kNone;
    }
    ++stats_.sequence_packets;
  }
  ++stats_.accepted;

  const std::uint16_t rpm = packet.motor_rpm();
  const ReturnMode mode = packet.return_mode();
  stats_.rpm_min = stats_.accepted == 1 ? rpm : std::min(stats_.rpm_min, rpm);
  stats_.rpm_max = stats_.accepted == 1 ? rpm : std::max(stats_.rpm_max, rpm);
  if (stats_.return_mode && *stats_.return_mode != mode) ++stats_.return_mode_changes;
  stats_.return_mode = mode;
  const bool high_temperature = packet.tail_bytes()[5] != 0;
  if (high_temperature) ++stats_.high_temperature;
  const bool sequence_present = packet.sequence().has_value();

  const PacketTime time = clock_.convert(packet.utc(), packet.timestamp_us());
  if (time.status == PacketTimeStatus::kBadDate) ++stats_.bad_date;
  if (time.status == PacketTimeStatus::kBadMicroseconds) ++stats_.bad_microseconds;
  if (previous_t0_ns_) {
    // Counted as they arrive, outliers included: the health reports each. Frames are cut by
    // azimuth; a time that freezes changes no frame, and one that leaps or steps back is either
    // an outlier (left out) or a real gap (the assembler ends the frame in progress).
    if (time.t0_ns == *previous_t0_ns_) ++stats_.static_timestamps;
    if (time.t0_ns < *previous_t0_ns_) ++stats_.backward_timestamps;
    if (time.t0_ns - *previous_t0_ns_ > kTimestampJumpNs) ++stats_.timestamp_jumps;
  }
  track_azimuth(packet.azimuth_cdeg(0), time.t0_ns, rpm, mode, sequence_present);
  previous_t0_ns_ = time.t0_ns;
  stats_.last_t0_ns = time.t0_ns;
  stats_.last_time_valid = time.status == PacketTimeStatus::kValid;
  stats_.last_rpm = rpm;
  stats_.last_high_temperature = high_temperature;

  place_or_hold(payload, Admitted{{packet.azimuth_cdeg(0), time.t0_ns, time.valid(), rpm}, time});
  return RejectReason::kNone;
}

void StreamDecoder::place_or_hold(std::span<const std::uint8_t> payload, const Admitted& admitted) {
  if (held_size_ != 0) {
    const std::span<const std::uint8_t> held(held_bytes_.data(), held_size_);
    if (last_placed_ && follows(*last_placed_, admitted.rotation)) {
      // The stream went on as if the held packet had not been there: an isolated outlier.
      settle_outlier(*last_placed_, admitted.rotation);
    } else if (follows(held_.rotation, admitted.rotation)) {
      place(held, held_);  // the stream changed at the held packet: a real change
      held_size_ = 0;
      place(payload, admitted);
      return;
    } else {
      drop_held_as_outlier();  // followed by nothing: judge this one in its place
    }
  }
  if (!last_placed_ || follows(*last_placed_, admitted.rotation)) {
    place(payload, admitted);
  } else {
    hold(payload, admitted);
  }
}

void StreamDecoder::hold(std::span<const std::uint8_t> payload, const Admitted& admitted) {
  std::memcpy(held_bytes_.data(), payload.data(), payload.size());
  held_size_ = payload.size();
  held_ = admitted;
}

void StreamDecoder::settle_outlier(const RotationPoint& before, const RotationPoint& after) {
  ++stats_.outliers;
  const int to_held = signed_step(held_.rotation.azimuth_cdeg, before.azimuth_cdeg);
  const int to_after = signed_step(after.azimuth_cdeg, before.azimuth_cdeg);
  const std::int64_t dt = after.t0_ns - before.t0_ns;
  if (to_held >= 0 && to_held <= to_after && to_after > 0 && dt > 0 && before.time_valid &&
      after.time_valid) {
    // Its azimuth sits between its neighbours': only its time is wrong. Placed where it belongs,
    // at the time the rotation gives that azimuth, its points kept.
    Admitted fixed = held_;
    fixed.time.t0_ns = before.t0_ns + dt * to_held / to_after;
    fixed.time.status = PacketTimeStatus::kValid;
    fixed.rotation.t0_ns = fixed.time.t0_ns;
    fixed.rotation.time_valid = true;
    const std::span<const std::uint8_t> held(held_bytes_.data(), held_size_);
    held_size_ = 0;
    place(held, fixed);
    return;
  }
  // Out of the rotation's order in azimuth: left out, its slots counted.
  stats_.filtered.add(FilterReason::kOutlier, std::uint64_t{kBlocks} * kChannels);
  held_size_ = 0;
}

void StreamDecoder::drop_held_as_outlier() noexcept {
  ++stats_.outliers;
  stats_.filtered.add(FilterReason::kOutlier, std::uint64_t{kBlocks} * kChannels);
  held_size_ = 0;
}

void StreamDecoder::place(std::span<const std::uint8_t> payload, const Admitted& admitted) {
  if (!decode_points_) {  // the health needs only where the rotation is
    last_placed_ = admitted.rotation;
    return;
  }
  const PacketView packet = PacketView::assume_valid(payload);
  const DecodedPacket decoded =
      decoder_.decode(packet, admitted.time.t0_ns, points_, stats_.filtered);
  stats_.points += decoded.point_count;

  PacketMeta meta;
  for (int b = 0; b < kBlocks; ++b)
    meta.block_azimuth_cdeg[b] = packet.azimuth_cdeg(b);
  meta.t0_ns = admitted.time.t0_ns;
  meta.time_valid = admitted.time.valid();
  meta.motor_rpm = admitted.rotation.rpm;
  meta.return_mode = packet.return_mode();
  assembler_.add_packet(meta, std::span<const Point>(points_).first(decoded.point_count), decoded);
  last_placed_ = admitted.rotation;
}

void StreamDecoder::flush() {
  if (held_size_ != 0) {
    // Nothing came after it to say it was an outlier: it is placed.
    place(std::span<const std::uint8_t>(held_bytes_.data(), held_size_), held_);
    held_size_ = 0;
  }
  assembler_.flush();
  last_placed_.reset();
}

}  // namespace pandarcap
