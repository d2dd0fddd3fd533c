#include "stream_decoder.hpp"

#include <algorithm>

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

}  // namespace

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
      assembler_(assembler_config(decoder_.scalar(), config.cut_angle_deg), sink) {}

RejectReason StreamDecoder::process(std::span<const std::uint8_t> payload) {
  ++stats_.packets;
  const RejectReason reason = validate(payload);
  ++stats_.rejects[static_cast<std::size_t>(reason)];
  if (reason != RejectReason::kNone) return reason;
  ++stats_.accepted;

  const PacketView packet = PacketView::assume_valid(payload);
  const std::uint16_t rpm = packet.motor_rpm();
  const ReturnMode mode = packet.return_mode();
  stats_.rpm_min = stats_.accepted == 1 ? rpm : std::min(stats_.rpm_min, rpm);
  stats_.rpm_max = stats_.accepted == 1 ? rpm : std::max(stats_.rpm_max, rpm);
  if (stats_.return_mode && *stats_.return_mode != mode) ++stats_.return_mode_changes;
  stats_.return_mode = mode;
  const bool high_temperature = packet.tail_bytes()[5] != 0;
  if (high_temperature) ++stats_.high_temperature;
  const bool sequence_present = packet.sequence().has_value();
  if (const auto sequence = packet.sequence()) {
    ++stats_.sequence_packets;
    sequence_.observe(*sequence);
  }

  const PacketTime time = clock_.convert(packet.utc(), packet.timestamp_us());
  if (time.status == PacketTimeStatus::kBadDate) ++stats_.bad_date;
  if (time.status == PacketTimeStatus::kBadMicroseconds) ++stats_.bad_microseconds;
  if (previous_t0_ns_) {
    // Counted, not corrected: frames are cut by azimuth, so a clock that freezes or steps back
    // (a PTP/GPS resync) changes no frame; a leap of more than half a revolution is a gap to the
    // assembler and ends the frame in progress, as a loss would. The health reports each.
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

  const DecodedPacket decoded = decoder_.decode(packet, time.t0_ns, points_, stats_.filtered);
  stats_.points += decoded.point_count;

  PacketMeta meta;
  for (int b = 0; b < kBlocks; ++b)
    meta.block_azimuth_cdeg[b] = packet.azimuth_cdeg(b);
  meta.t0_ns = time.t0_ns;
  meta.time_valid = time.valid();
  meta.motor_rpm = rpm;
  meta.return_mode = mode;
  assembler_.add_packet(meta, std::span<const Point>(points_).first(decoded.point_count), decoded);
  return RejectReason::kNone;
}

}  // namespace pandarcap
