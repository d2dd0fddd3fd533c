// The Pandar40P's rotation in numbers, in one place: how many packets a second it sends, how many
// a revolution has, how far the azimuth steps from one packet to the next. The stream rules judge
// a stream against them: the outlier rule and the standing motor (core/decode/stream_decoder.hpp),
// the frame's completeness (core/decode/frame_assembler.hpp), the measured speed and the packet
// rate in the health (core/health/health_policy.hpp). Issue 39 makes these one model's facts among
// several.
//
// The 40P fires on a time base: a firing round every 55.56 µs whatever the motor's speed
// (core/sensors/timing.hpp), 10 rounds to a single-return packet, 5 to a dual one (its blocks
// paired). So its packet rate is fixed, and the speed sets how far each packet turns:
//
//   return   packets/s   per revolution at 600 RPM   step per packet at 600 RPM
//   single   1800        180                         2° (0.2° per block)
//   dual     3600        360                         1° (blocks paired, 0.2° per pair)
#pragma once

#include "core/sensors/packet.hpp"
#include "core/sensors/timing.hpp"

namespace pandarcap {

inline constexpr double kFullCircleCdeg = 36000.0;

// The motor speeds the sensor is set to (its web page and PTC offer 300, 600 and 1200 RPM).
inline constexpr int kSlowestRpm = 300;
inline constexpr int kFastestRpm = 1200;

constexpr double packets_per_second(ReturnMode mode) noexcept {
  return 1e9 / static_cast<double>(packet_period_ns(mode));
}

// 0 for a motor that does not turn.
constexpr double packets_per_revolution(ReturnMode mode, double rpm) noexcept {
  return rpm > 0 ? packets_per_second(mode) * 60.0 / rpm : 0.0;
}

// The first block's azimuth advance from one packet to the next (0.01°): 100 at 600 RPM dual.
constexpr double azimuth_step_per_packet_cdeg(ReturnMode mode, double rpm) noexcept {
  return rpm / 60.0 * kFullCircleCdeg * static_cast<double>(packet_period_ns(mode)) * 1e-9;
}

// A packet whose first block's azimuth moved less than this from the last packet placed did not
// turn: 0.05°, a motor below 15 RPM in single return, 30 in dual (at 300 RPM, the slowest, a
// dual packet still turns 0.5°). The encoder's jitter on a turning motor is 0.01-0.02°.
inline constexpr int kStandingStepCdeg = 5;

// How far a packet's first azimuth may stray from where the time since an earlier packet puts it
// (at the earlier one's tail speed) and still follow it: the encoder's jitter and a seam, plus a
// share of the way for the tail's speed against the motor's. Measured on the real capture (1439
// packets, tails of 598, 600 and 602 RPM, its own tail times): a packet strays at most 0.026°
// from where the time and the tail's speed put it; over n packets the speed's share grows to
// 0.9 % of the way (n = 10: 0.086°, 17: 0.15°, 100: 0.76°, 179: 1.0°). The capture looped (as
// the tests and a re-timed replay send it) steps 0.15° short where its end joins its start: a
// shift the rotation keeps, which must not be a change. So 0.2° + 1 %: a dual packet (1°) may
// be 0.21° off, 17 of them 0.37°, half a revolution 2°. A packet shifted by 0.25° or more does not
// follow; a smaller shift is placed as it is (its points that far off).
inline constexpr double kFollowJitterCdeg = 20;
inline constexpr double kFollowSpeedShare = 0.01;
constexpr double follow_tolerance_cdeg(double expected_cdeg) noexcept {
  return kFollowJitterCdeg +
         kFollowSpeedShare * (expected_cdeg < 0 ? -expected_cdeg : expected_cdeg);
}

// The packets a frame can hold: one revolution's at the tail's speed, widened by the channels'
// azimuth offsets (a frame's points reach past its revolution's ends by them: 8.3° with the real
// calibration) and one packet (the one a frame's first and last points share), with the tail's
// speed share (kFollowSpeedShare) and two packets to spare for reordering. The real capture's
// whole frames hold 364-369 packets at 598-602 RPM; this is 371-376.
// The same for a model sending `packets_per_second` in the stream's return mode.
constexpr double frame_packet_limit_at(double packets_per_second, double rpm,
                                       double channel_span_cdeg) noexcept {
  const double per_revolution = rpm > 0 ? packets_per_second * 60.0 / rpm : 0.0;
  return per_revolution * (1 + channel_span_cdeg / kFullCircleCdeg) * (1 + kFollowSpeedShare) + 1 +
         2;
}
constexpr double frame_packet_limit(ReturnMode mode, double rpm,
                                    double channel_span_cdeg) noexcept {
  const double per_revolution = packets_per_revolution(mode, rpm);
  return per_revolution * (1 + channel_span_cdeg / kFullCircleCdeg) * (1 + kFollowSpeedShare) + 1 +
         2;
}

}  // namespace pandarcap
