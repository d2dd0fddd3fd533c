// The decode path for a stream of payloads, as one pure object: validate -> duplicates -> tail
// -> packet time -> outliers -> decode -> frame assembly, counting everything on the way. The
// daemon's decode worker, pandarcap-inspect and the tests all run packets through this.
//
// Duplicates: a payload with the same bytes as one of the last kDuplicateWindow (a switch loop, a
// mirror port), or whose UDP sequence number has already arrived at the time it says (a number
// seen before at a new time is the sensor's counter restarting: core/decode/sequence_tracker.hpp),
// is counted and not decoded again.
//
// The outlier rule: a glitch costs its packets, not the revolution around it. A packet that
// does not follow the last one placed (follows(), core/decode/outlier_rule.hpp) is held back, with
// the ones after it, up to kMaxHeldPackets (16). The run is decided by what comes next:
//  - the stream goes on: a packet follows the last one placed again. The held run was outliers,
//    each counted (outliers). One whose azimuth sits between its neighbours' had only its time
//    wrong: it is placed where it belongs, at the time the rotation gives its azimuth. One out of
//    the azimuths' order is left out (its channel slots filtered as kOutlier), and the frame
//    assembler is told how many packets were left out there (PacketMeta::skipped_before), so the
//    revolution stays whole;
//  - the stream changed: kChangeRunPackets (17) packets follow each other and not the last one
//    placed (a sensor restart, a long gap, a new speed, a clock that stepped for good). They are
//    placed, and the frame assembler cuts as before (told to, when the rotation resumes behind
//    where it was); held packets that were not part of that run are outliers.
// With no packet placed yet (the start, after flush()), the first 17 that follow each other
// start the stream, so a glitch right after the start is an outlier too. flush() places the run
// in progress.
// Timestamp counters are judged against the stream, not the packet before: an outlier whose time
// is behind the stream's went back (backward_timestamps), one ahead of the packets after it leapt
// forward (timestamp_jumps); a change that stepped the clock back, or more than a second on,
// likewise. The packet that returns to the stream after a glitch is not counted.
//
// A standing motor: a packet whose first azimuth moved less than kStandingStepCdeg from the
// previous packet's (core/sensors/sensor_model.hpp) did not turn. It is counted (standing), its
// slots filtered as kStanding, and never placed: a stopped motor must not pile revolutions of
// packets into one frame. When the motor turns again after a pause, the time gap cuts the frame.
//
// Counting rules (so every payload is accounted for):
//   packets = accepted + sum(rejects) + duplicates
//   every channel slot of an accepted packet is a point or a filtered count (by reason).
// With decode_points off (StreamDecoderConfig) the first identity still holds; the second is
// not counted.
// Not thread-safe; one per decode thread. No allocation after construction.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <span>

#include "core/decode/calibration.hpp"
#include "core/decode/decoder.hpp"
#include "core/decode/decoder_target.hpp"
#include "core/decode/frame_assembler.hpp"
#include "core/decode/outlier_rule.hpp"
#include "core/decode/packet_decoder.hpp"
#include "core/decode/packet_time.hpp"
#include "core/decode/sequence_tracker.hpp"
#include "core/sensors/packet.hpp"

namespace pandarcap {

struct StreamDecoderConfig {
  DecoderConfig decoder;
  DecoderTarget decoder_target = DecoderTarget::kScalar;  // callers resolve "auto"
  double cut_angle_deg = 0.0;
  // false: nothing consumes points (the daemon with output.frames and output.mcap off). Only
  // what the health needs is done: validation, duplicates and the UDP sequence, the tail (status,
  // RPM, time, return mode), azimuth tracking and the outlier rule; no point is decoded and no
  // frame cut. stats().points, stats().filtered and frames() then mean "not counted", not
  // "none" (the health leaves them out: docs/daemon.md, "Recording only").
  bool decode_points = true;
};

// Consecutive packets are 0.28 to 0.56 ms apart; a second is far more than any loss the sequence
// or azimuth checks would not already show.
inline constexpr std::int64_t kTimestampJumpNs = 1'000'000'000;

// How many recent payloads a duplicate is looked for among: 18 ms of a dual-return stream, far
// longer than a switch loop or a mirror port delays a copy.
inline constexpr std::size_t kDuplicateWindow = 64;

struct StreamStats {
  std::uint64_t packets = 0;
  std::uint64_t accepted = 0;
  std::array<std::uint64_t, kRejectReasonCount> rejects{};  // indexed by RejectReason
  std::uint64_t bad_date = 0;             // accepted, absolute time invalid (date out of range)
  std::uint64_t bad_microseconds = 0;     // accepted, µs field > 1'000'000
  std::uint64_t static_timestamps = 0;    // packet time did not advance from the previous packet
  std::uint64_t backward_timestamps = 0;  // packet time went back from the stream's (see above)
  // Packet time leapt forward: an outlier ahead of the packets after it, or the stream's clock
  // stepping more than kTimestampJumpNs on.
  std::uint64_t timestamp_jumps = 0;
  std::uint64_t high_temperature = 0;  // packets with the shutdown flag set
  std::uint64_t return_mode_changes = 0;
  std::uint64_t duplicates = 0;  // not decoded again (see the top of this file)
  std::uint64_t outliers = 0;    // glitches; placed with their time fixed, or filtered kOutlier
  std::uint64_t standing = 0;    // the motor did not turn: filtered kStanding, never placed
  // Packets accepted while no frame had closed for three revolutions' worth of packets (at the
  // tail's speed, 300 RPM at the least): a motor that does not turn, or an azimuth that goes
  // nowhere. Counted only where frames are cut (decode_points).
  std::uint64_t frameless_packets = 0;
  std::uint64_t sequence_packets = 0;      // accepted packets that carried a UDP sequence
  std::optional<ReturnMode> return_mode;   // of the last accepted packet
  std::uint16_t rpm_min = 0, rpm_max = 0;  // over accepted packets (0 before the first)
  std::uint64_t points = 0;
  FilterCounts filtered;
  // Without a UDP sequence, loss shows as an azimuth step between consecutive packets larger
  // than the tail RPM allows (more than 1.5 packets' worth plus 0.05°).
  std::uint64_t azimuth_gaps = 0;
  // Measured spin: forward azimuth steps between consecutive packets (0.01°) and the packet time
  // they took (ns), summed over steps that are one packet apart in time (at most 1.5 packet
  // periods: no loss, no glitch) and no gap. A standing motor's steps are 0: it measures 0 RPM.
  // RPM over any interval = (delta azimuth / 36000) / (delta time in minutes).
  std::uint64_t measured_azimuth_cdeg = 0;
  std::uint64_t measured_time_ns = 0;
  // Packet rate by the sensor's own clock: accepted packets, and the time from the packet before
  // (in arrival order, both times valid, 0 to 100 ms apart), summed. Packets per second over any
  // interval = delta packets / delta time. Two streams merged on one port count twice the
  // packets in the same time.
  std::uint64_t rate_packets = 0;
  std::uint64_t rate_time_ns = 0;
  // The last accepted packet.
  std::int64_t last_t0_ns = 0;
  bool last_time_valid = false;  // its tail's date and microseconds made a real time
  std::uint16_t last_rpm = 0;
  bool last_high_temperature = false;

  std::uint64_t rejected() const noexcept;
  std::uint64_t rejects_for(RejectReason r) const noexcept {
    return rejects[static_cast<std::size_t>(r)];
  }
};

class StreamDecoder {
 public:
  StreamDecoder(const Calibration& calibration, const StreamDecoderConfig& config, FrameSink& sink);

  // Processes one UDP payload; returns why it was rejected, or kNone (a duplicate too: it is not
  // malformed, see stats().duplicates).
  RejectReason process(std::span<const std::uint8_t> payload);
  // End of stream: the held run is placed, open frames are finished as partial.
  void flush();

  const StreamStats& stats() const noexcept { return stats_; }
  const SequenceStats& sequence() const noexcept { return sequence_.stats(); }
  const AssemblerStats& frames() const noexcept { return assembler_.stats(); }
  const ScalarDecoder& decoder() const noexcept { return decoder_.scalar(); }
  DecoderTarget decoder_target() const noexcept { return decoder_.target(); }

 private:
  void track_azimuth(std::uint16_t azimuth_cdeg, std::int64_t t0_ns, bool time_valid,
                     std::uint16_t rpm, ReturnMode mode, bool sequence_present);
  bool duplicate(std::span<const std::uint8_t> payload) noexcept;
  // The outlier rule: places `payload` now, or holds it back, and decides the held run.
  void place_or_hold(std::span<const std::uint8_t> payload, const AdmittedPacket& admitted);
  // Decodes `payload` and gives its points to the frame assembler.
  void place(std::span<const std::uint8_t> payload, const AdmittedPacket& admitted);
  // The held run was outliers between the last packet placed and `after`, which follows it:
  // each placed with its time re-derived from its azimuth when only its time was wrong, else
  // left out.
  void settle_outliers(const RotationPoint& after);
  // The held chain is the stream now: the strays before it are outliers, the chain is placed.
  void take_change();
  void drop_oldest_as_outlier() noexcept;
  void filter_packet(FilterReason reason) noexcept;
  // Frames that do not close while packets arrive (frameless_packets).
  void watch_frames(std::uint16_t rpm, ReturnMode mode) noexcept;

  PacketDecoder decoder_;
  FrameAssembler assembler_;
  bool decode_points_;
  PacketClock clock_;
  SequenceTracker sequence_;
  StreamStats stats_;
  std::optional<std::int64_t> previous_t0_ns_;
  bool previous_time_valid_ = false;
  std::optional<std::uint16_t> previous_azimuth_cdeg_;  // first block of the previous packet
  std::array<Point, kMaxPointsPerPacket> points_{};
  // Fingerprints of the last kDuplicateWindow accepted payloads (0: empty), a ring.
  std::array<std::uint64_t, kDuplicateWindow> recent_{};
  std::size_t recent_next_ = 0;
  std::optional<RotationPoint> last_placed_;
  HeldPackets held_;
  // Packets left out (outliers, standing) since the last one placed: the frame assembler's
  // allowance for the azimuth they leave uncovered.
  std::uint32_t skipped_ = 0;
  // Frames closed so far, and packets accepted since the last one closed.
  std::uint64_t frames_closed_ = 0;
  std::uint64_t packets_since_frame_ = 0;
};

}  // namespace pandarcap
