// The decode path for a stream of payloads, as one pure object: validate -> tail -> packet time
// -> scalar decode -> frame assembly, counting everything on the way. The daemon's decode worker,
// pandarcap-inspect and the tests all run packets through this.
//
// Counting rules (so every payload is accounted for):
//   packets = accepted + sum(rejects)
//   every channel slot of an accepted packet is a point or a filtered count (by reason).
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
};

// Consecutive packets are 0.28 to 0.56 ms apart; a second is far more than any loss the sequence
// or azimuth checks would not already show.
inline constexpr std::int64_t kTimestampJumpNs = 1'000'000'000;

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

  // Processes one UDP payload; returns why it was rejected, or kNone.
  RejectReason process(std::span<const std::uint8_t> payload);
  // End of stream: open frames are finished as partial.
  void flush() { assembler_.flush(); }

  const StreamStats& stats() const noexcept { return stats_; }
  const SequenceStats& sequence() const noexcept { return sequence_.stats(); }
  const AssemblerStats& frames() const noexcept { return assembler_.stats(); }
  const ScalarDecoder& decoder() const noexcept { return decoder_.scalar(); }
  DecoderTarget decoder_target() const noexcept { return decoder_.target(); }

 private:
  void track_azimuth(std::uint16_t azimuth_cdeg, std::int64_t t0_ns, std::uint16_t rpm,
                     ReturnMode mode, bool sequence_present);

  PacketDecoder decoder_;
  FrameAssembler assembler_;
  PacketClock clock_;
  SequenceTracker sequence_;
  StreamStats stats_;
  std::optional<std::int64_t> previous_t0_ns_;
  std::optional<std::uint16_t> previous_azimuth_cdeg_;  // first block of the previous packet
  std::array<Point, kMaxPointsPerPacket> points_{};
};

}  // namespace pandarcap
