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
// does not follow the last one placed (follows(), core/decode/outlier_rule.hpp: within 0.06° of
// where its time puts it, for a dual packet) is held back, with the ones after it, up to
// kMaxHeldPackets (16). The run is decided by what comes next:
//  - the stream goes on: a packet follows the last one placed again. The held run was outliers,
//    each counted (outliers) and repaired where one of its two coordinates is right: the run's
//    packets have their places between the two neighbours (the k-th of n held, when the time
//    says no packet was lost among them; else in order between the neighbours' times and
//    azimuths). One whose time is at its place had its azimuth shifted: every block's azimuth
//    is re-derived from its time (one shift for the packet, patched in the held copy) and it is
//    placed. One whose azimuth is at its place had its time wrong (back, forward, a second off,
//    zeroed): placed at the time the rotation gives its azimuth. One with neither is left out
//    (its channel slots filtered as kOutlier): its frame lacks its points and is partial, and the
//    frame assembler is told a packet was left out there (PacketMeta::skipped_before), so it is
//    not counted as lost;
//  - the stream changed: kChangeRunPackets (17) packets follow each other and not the last one
//    placed (a sensor restart, a long gap, a new speed, a clock that stepped for good, a stream
//    turning backwards). They are taken: the frames in progress end (partial) and the change is
//    counted (stream_changes); held packets that were not part of that run are outliers.
// With no packet placed yet (the start, after flush()), the first 17 that follow each other
// start the stream, so a glitch right after the start is an outlier too. flush() places the run
// in progress.
// A stream turning backwards is taken like any change, and from then on its packets (those that
// follow the last one backwards) are counted (reversed) and filtered as kReversed, never placed:
// frames are cut by a rotation that turns forwards. 17 that turn forwards again are a change back.
// Timestamp counters are judged against the stream, not the packet before: an outlier whose time
// is behind the stream's went back (backward_timestamps), one ahead of the packets after it leapt
// forward (timestamp_jumps). A change whose clock stepped back counts once as going back; one
// whose clock stepped forward while its azimuth went on as if only its packets' time had passed
// (a clock that leapt, not a gap) counts once as leaping forward.
//
// A standing motor: a packet whose first azimuth moved less than kStandingStepCdeg from the last
// packet placed and from the packet before (core/sensors/sensor_model.hpp) did not turn. It is
// counted (standing), its slots filtered as kStanding, and never placed: a stopped motor must not
// pile revolutions of packets into one frame. When the motor turns again after a pause, the
// stream has changed (its time went on without the azimuth): the frames are cut. Judged against
// the last packet placed too: the packet that returns to the stream after a glitch is no
// standing motor. The first that stands, when the times say it should have turned, is held as a
// glitch (a packet shifted back a step lands there): the second that stands counts both.
//
// Counting rules (so every payload is accounted for):
//   packets = accepted + sum(rejects) + duplicates
//   every channel slot of an accepted packet is a point or a filtered count (by reason);
//   every point is in a frame, late, or dropped (frame full, no frame): AssemblerStats.
// With decode_points off (StreamDecoderConfig) the first identity still holds; the second is
// not counted.
// Not thread-safe; one per decode thread. No allocation after construction.
#pragma once

#include <array>
#include <concepts>
#include <cstdint>
#include <optional>
#include <span>

#include "core/decode/calibration.hpp"
#include "core/decode/decoder.hpp"
#include "core/decode/decoder_target.hpp"
#include "core/decode/frame_assembler.hpp"
#include "core/decode/model_decoder.hpp"
#include "core/decode/outlier_rule.hpp"
#include "core/decode/packet_decoder.hpp"
#include "core/decode/packet_time.hpp"
#include "core/decode/sequence_tracker.hpp"
#include "core/sensors/packet.hpp"
#include "core/sensors/pandar40p.hpp"

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
  // Glitches: placed with their time or their azimuth re-derived from the other, or filtered
  // kOutlier when neither is right.
  std::uint64_t outliers = 0;
  std::uint64_t standing = 0;  // the motor did not turn: filtered kStanding, never placed
  std::uint64_t reversed = 0;  // the azimuth running backwards: filtered kReversed, never placed
  // Changes taken (17 packets that follow each other and not the stream): the frames in progress
  // end there. The stream's start is none.
  std::uint64_t stream_changes = 0;
  // The last invalid time's first field out of range, and its value (kNone: none yet).
  TimeField last_invalid_field = TimeField::kNone;
  std::uint32_t last_invalid_value = 0;
  // Packets accepted while no frame had closed for three revolutions' worth of packets (at the
  // tail's speed, 300 RPM at the least): a motor that does not turn, or an azimuth that goes
  // nowhere. Counted only where frames are cut (decode_points).
  std::uint64_t frameless_packets = 0;
  std::uint64_t sequence_packets = 0;      // accepted packets that carried a UDP sequence
  std::optional<ReturnMode> return_mode;   // of the last accepted packet
  std::uint16_t rpm_min = 0, rpm_max = 0;  // over accepted packets (0 before the first)
  std::uint64_t points = 0;
  FilterCounts filtered;
  // Without a UDP sequence, loss shows as an azimuth step between consecutive packets placed
  // larger than the tail RPM allows (more than 1.5 packets' worth plus 0.05°, plus the packets
  // left out between them).
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

// Packets lost, for points_missing: the UDP sequence's count when the packets carry one, else the
// azimuth the frames lacked (AssemblerStats::packets_missing). Never from the time: a clock that
// steps, a glitch, a standing motor look like lost packets by their times.
inline std::uint64_t packets_missing(const StreamStats& stream, const SequenceStats& sequence,
                                     const AssemblerStats& frames) noexcept {
  return stream.sequence_packets > 0 ? sequence.lost : frames.packets_missing;
}

// One per model (core/sensors/sensor_models.hpp), instantiated in stream_decoder.cpp for every
// supported model; StreamDecoder is the Pandar40P's. Everything the rules need of a packet comes
// through Model's accessors, so no packet pays a branch on the model.
template <class Model>
class BasicStreamDecoder {
 public:
  using ModelType = Model;
  // Throws std::invalid_argument when the calibration is not the model's channel count.
  BasicStreamDecoder(const Calibration& calibration, const StreamDecoderConfig& config,
                     FrameSink& sink);

  // Processes one UDP payload; returns why it was rejected, or kNone (a duplicate too: it is not
  // malformed, see stats().duplicates).
  RejectReason process(std::span<const std::uint8_t> payload);
  // End of stream: the held run is placed, open frames are finished as partial.
  void flush();
  // Adds what another model's decoder counted before this one took its place (a live "auto"
  // switching at the first packet of its model: nothing was accepted yet), so the counts go on.
  void count_before(const StreamStats& before) noexcept {
    stats_.packets += before.packets;
    for (std::size_t r = 0; r < kRejectReasonCount; ++r)
      stats_.rejects[r] += before.rejects[r];
    stats_.duplicates += before.duplicates;
  }

  const StreamStats& stats() const noexcept { return stats_; }
  const SequenceStats& sequence() const noexcept { return sequence_.stats(); }
  const AssemblerStats& frames() const noexcept { return assembler_.stats(); }
  // Packets lost (see packets_missing() below).
  std::uint64_t packets_missing() const noexcept {
    return pandarcap::packets_missing(stats_, sequence_.stats(), assembler_.stats());
  }
  // The Pandar40P's scalar reference (a member template, so the other models' explicit
  // instantiations do not instantiate it).
  template <class M = Model>
  requires std::same_as<M, Pandar40P>
  const ScalarDecoder& decoder() const noexcept { return decoder_.scalar(); }
  DecoderTarget decoder_target() const noexcept { return decoder_.target(); }

 private:
  void track_azimuth(std::uint16_t azimuth_cdeg, std::int64_t t0_ns, bool time_valid,
                     std::uint16_t rpm, ReturnMode mode);
  bool duplicate(std::span<const std::uint8_t> payload) noexcept;
  // The outlier rule: places `payload` now, or holds it back, and decides the held run.
  void place_or_hold(std::span<const std::uint8_t> payload, const AdmittedPacket& admitted);
  // Decodes `payload` and gives its points to the frame assembler.
  void place(std::span<const std::uint8_t> payload, const AdmittedPacket& admitted);
  // The held run was outliers between the last packet placed and `after`, which follows it:
  // each repaired and placed where its time or its azimuth says, else left out.
  void settle_outliers(const RotationPoint& after);
  // Held packet i, repaired to sit `at` (0.01°) past `before` at time `t0_ns` (its own, or
  // re-derived), the rotation turning `packet_step` a packet: placed.
  void place_repaired(std::size_t i, const RotationPoint& before, int at_cdeg, std::int64_t t0_ns,
                      double packet_step_cdeg);
  // The held chain is the stream now: the strays before it are outliers, the chain is placed.
  // `counted`: a change of the stream (not its start, nor the end of input).
  void take_change(bool counted);
  void drop_oldest_as_outlier() noexcept;
  void filter_packet(FilterReason reason) noexcept;
  // Frames that do not close while packets arrive (frameless_packets).
  void watch_frames(std::uint16_t rpm, ReturnMode mode) noexcept;

  ModelDecoder<Model> decoder_;
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
  Turning turning_ = Turning::kForward;  // the stream's, as the last change took it
  bool stood_ = false;                   // the packet before was counted standing
  std::uint64_t placed_arrival_ = 0;     // the last packet placed's AdmittedPacket::arrival
  HeldPackets held_;
  // Outliers left out since the last one placed: the frame assembler's word that the azimuth
  // they leave uncovered was not lost.
  std::uint32_t skipped_ = 0;
  bool sequence_present_ = false;  // the packet being processed carried a UDP sequence
  // The tail's speed as the stream has it: a value is taken once two packets in a row carry it
  // (or at the first packet), so that one glitched byte does not change the speed the outlier
  // rule expects (a real change of speed moves the azimuth too, which follows() allows for).
  std::optional<std::uint16_t> stream_rpm_;
  std::uint16_t previous_tail_rpm_ = 0;
  // The stream's return mode, and the packets in a row that carry another one: up to
  // kMaxHeldPackets of them are a glitch of that byte, each decoded in the stream's mode from
  // a copy with the byte mended (repaired_) and counted as an outlier; the next is a change of
  // mode, taken.
  std::optional<ReturnMode> stream_mode_;
  ReturnMode other_mode_ = ReturnMode::kDual;
  std::uint32_t other_mode_run_ = 0;
  std::array<std::uint8_t, kMaxPacketBytes> repaired_{};
  // Frames closed so far, and packets accepted since the last one closed.
  std::uint64_t frames_closed_ = 0;
  std::uint64_t packets_since_frame_ = 0;
};

using StreamDecoder = BasicStreamDecoder<Pandar40P>;

}  // namespace pandarcap
