// The decode path for a stream of payloads, as one pure object: validate -> duplicates -> tail
// -> packet time -> outliers -> decode -> frame assembly, counting everything on the way. The
// daemon's decode worker, pandarcap-inspect and the tests all run packets through this.
//
// Duplicates: a payload with the same bytes as one of the last kDuplicateWindow (a switch loop, a
// mirror port), or whose UDP sequence number has already arrived, is counted and not decoded
// again.
//
// Outliers: one packet whose time or azimuth does not follow the rotation (a time that goes
// back or leaps, an azimuth out of order) must not cost the revolution around it. A packet that
// does not follow the last one placed (follows(), below) is held back, and the next packet
// decides: if that one follows the last one placed, the held packet was an isolated outlier,
// counted (outliers), and the frame in progress is untouched. An outlier whose azimuth sits
// between its neighbours' had only its time wrong: it is placed where it belongs, at the time the
// rotation gives its azimuth. One out of the azimuths' order is left out (its channel slots
// filtered as kOutlier).
// If the next one follows the held packet instead, the change is real (a sensor restart, a long
// gap, a new speed): the held packet is placed, and the frame assembler cuts as before. If it
// follows neither, the held packet is dropped as an outlier and the next one is judged in its
// place. A packet is held at most until the next one arrives (or flush()).
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

#include "calibration.hpp"
#include "decoder.hpp"
#include "decoder_target.hpp"
#include "frame_assembler.hpp"
#include "packet.hpp"
#include "packet_decoder.hpp"
#include "packet_time.hpp"
#include "sequence_tracker.hpp"

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

// Where a packet sits in the rotation: what follows() compares.
struct RotationPoint {
  std::uint16_t azimuth_cdeg = 0;  // the first block's
  std::int64_t t0_ns = 0;
  bool time_valid = false;
  std::uint16_t rpm = 0;  // the tail's motor speed
};

// Whether `next` follows `last` in one rotation. With valid times that moved, the azimuth must
// have advanced by what the time took at `last`'s speed (within 2° + 2 %), and by less than half
// a revolution: a packet loss, a reordered pair and a slow speed change all follow; a time that
// leaps or goes back, an azimuth out of order do not. Without usable times (invalid, frozen, no
// speed), the azimuth alone: a step of at most 90° either way.
bool follows(const RotationPoint& last, const RotationPoint& next) noexcept;

struct StreamStats {
  std::uint64_t packets = 0;
  std::uint64_t accepted = 0;
  std::array<std::uint64_t, kRejectReasonCount> rejects{};  // indexed by RejectReason
  std::uint64_t bad_date = 0;             // accepted, absolute time invalid (date out of range)
  std::uint64_t bad_microseconds = 0;     // accepted, µs field > 1'000'000
  std::uint64_t static_timestamps = 0;    // packet time did not advance from the previous packet
  std::uint64_t backward_timestamps = 0;  // packet time went back from the previous packet
  std::uint64_t timestamp_jumps = 0;      // packet time leapt forward by more than kTimestampJumpNs
  std::uint64_t high_temperature = 0;     // packets with the shutdown flag set
  std::uint64_t return_mode_changes = 0;
  std::uint64_t duplicates = 0;  // not decoded again (see the top of this file)
  std::uint64_t outliers = 0;    // isolated; placed with their time fixed, or filtered kOutlier
  std::uint64_t sequence_packets = 0;      // accepted packets that carried a UDP sequence
  std::optional<ReturnMode> return_mode;   // of the last accepted packet
  std::uint16_t rpm_min = 0, rpm_max = 0;  // over accepted packets (0 before the first)
  std::uint64_t points = 0;
  FilterCounts filtered;
  // Without a UDP sequence, loss shows as an azimuth step between consecutive packets larger
  // than the tail RPM allows (more than 1.5 packets' worth plus 0.05°).
  std::uint64_t azimuth_gaps = 0;
  // Measured spin: forward azimuth steps between consecutive packets (0.01°) and the packet time
  // they took (ns), summed over steps that are neither gaps nor discontinuities. RPM over any
  // interval = (delta azimuth / 36000) / (delta time in minutes).
  std::uint64_t measured_azimuth_cdeg = 0;
  std::uint64_t measured_time_ns = 0;
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
  // End of stream: a held packet is placed, open frames are finished as partial.
  void flush();

  const StreamStats& stats() const noexcept { return stats_; }
  const SequenceStats& sequence() const noexcept { return sequence_.stats(); }
  const AssemblerStats& frames() const noexcept { return assembler_.stats(); }
  const ScalarDecoder& decoder() const noexcept { return decoder_.scalar(); }
  DecoderTarget decoder_target() const noexcept { return decoder_.target(); }

 private:
  // A packet accepted and timed, waiting to be placed (or held back).
  struct Admitted {
    RotationPoint rotation;
    PacketTime time;
  };

  void track_azimuth(std::uint16_t azimuth_cdeg, std::int64_t t0_ns, std::uint16_t rpm,
                     ReturnMode mode, bool sequence_present);
  bool duplicate(std::span<const std::uint8_t> payload) noexcept;
  // The outlier rule: places `payload` now, or holds it back, or settles the one held.
  void place_or_hold(std::span<const std::uint8_t> payload, const Admitted& admitted);
  // Decodes `payload` and gives its points to the frame assembler.
  void place(std::span<const std::uint8_t> payload, const Admitted& admitted);
  void hold(std::span<const std::uint8_t> payload, const Admitted& admitted);
  // The held packet was an isolated outlier between `before` (placed) and `after` (the packet
  // that followed `before`): placed with its time re-derived from its azimuth when only its time
  // was wrong, else left out.
  void settle_outlier(const RotationPoint& before, const RotationPoint& after);
  void drop_held_as_outlier() noexcept;

  PacketDecoder decoder_;
  FrameAssembler assembler_;
  bool decode_points_;
  PacketClock clock_;
  SequenceTracker sequence_;
  StreamStats stats_;
  std::optional<std::int64_t> previous_t0_ns_;
  std::optional<std::uint16_t> previous_azimuth_cdeg_;  // first block of the previous packet
  std::array<Point, kMaxPointsPerPacket> points_{};
  // Fingerprints of the last kDuplicateWindow accepted payloads (0: empty), a ring.
  std::array<std::uint64_t, kDuplicateWindow> recent_{};
  std::size_t recent_next_ = 0;
  std::optional<RotationPoint> last_placed_;
  // The packet held back by the outlier rule, a copy of its bytes.
  std::array<std::uint8_t, kMaxPacketBytes> held_bytes_{};
  std::size_t held_size_ = 0;  // 0: none held
  Admitted held_;
};

}  // namespace pandarcap
