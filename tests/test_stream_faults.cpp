// The decode path's fault rules as matrices (core/decode/stream_decoder.hpp,
// core/decode/frame_assembler.hpp), on the real capture re-timed with a sensor's clock
// (support/retimed_capture.hpp) in every return mode: glitch bursts of every kind and length, and
// their neighbours (17 and more, at the cut, right after the start, with a loss); losses of 1 to
// 500 packets, in a revolution and at the cut; a motor that stands or crawls, its tail saying 0 or
// not; a counter that restarts at any moment; two streams merged on one port. Pure core, a
// StreamDecoder per case: the daemon's own runs of the same faults are in test_decode_faults.cpp.
#include <algorithm>
#include <array>
#include <catch2/catch.hpp>
#include <cstdint>
#include <cstring>
#include <functional>
#include <optional>
#include <vector>

#include "core/decode/calibration.hpp"
#include "core/decode/decoder_target.hpp"
#include "core/decode/stream_decoder.hpp"
#include "core/sensors/sensor_model.hpp"
#include "core/units.hpp"
#include "support/retimed_capture.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
using test::RetimedCapture;

namespace {

constexpr std::uint64_t kSlots = std::uint64_t{kBlocks} * kChannels;

// Keeps a few frames and what the test asks of each finished one.
class FrameTally final : public FrameSink {
 public:
  FrameTally() : storage_(kFrames * kDefaultFrameCapacityPoints) {
    for (std::size_t i = 0; i < kFrames; ++i) {
      frames_[i].points = std::span<Point>(storage_).subspan(i * kDefaultFrameCapacityPoints,
                                                             kDefaultFrameCapacityPoints);
      free_[i] = &frames_[i];
    }
  }
  Frame* acquire_frame() override { return free_count_ > 0 ? free_[--free_count_] : nullptr; }
  void frame_done(Frame& frame) override {
    points += frame.info.points;
    most_packets = std::max(most_packets, frame.info.packets);
    free_[free_count_++] = &frame;
  }
  void reset() { points = most_packets = 0; }

  std::uint64_t points = 0;        // in finished frames
  std::uint32_t most_packets = 0;  // the most packets one frame held

 private:
  static constexpr std::size_t kFrames = 3;
  std::vector<Point> storage_;
  std::array<Frame, kFrames> frames_{};
  std::array<Frame*, kFrames> free_{};
  std::size_t free_count_ = kFrames;
};

struct FaultOutcome {
  StreamStats stats;
  SequenceStats sequence;
  AssemblerStats frames;
  std::uint64_t points_in_frames = 0;
  std::uint32_t most_packets = 0;
};

// What a case does to packet k (its bytes, numbered from 0 with `sequence`): false drops it.
using Alter = std::function<bool(std::uint64_t k, std::span<std::uint8_t> packet)>;

FaultOutcome run_faults(const RetimedCapture& stream, std::uint64_t packets, const Alter& alter,
                        bool sequence = false) {
  static FrameTally tally;  // 17 MB of frames, allocated once for the file
  tally.reset();
  StreamDecoderConfig config;
  config.decoder_target = best_decoder_target();
  StreamDecoder decoder(Calibration::nominal(), config, tally);
  std::array<std::uint8_t, kMaxPacketBytes> buffer{};
  for (std::uint64_t k = 0; k < packets; ++k) {
    std::optional<std::uint32_t> number;
    if (sequence) number = static_cast<std::uint32_t>(k);
    const auto bytes = std::span(buffer).first(stream.packet(k, buffer, number));
    if (alter && !alter(k, bytes)) continue;
    decoder.process(bytes);
  }
  decoder.flush();
  return {decoder.stats(), decoder.sequence(), decoder.frames(), tally.points, tally.most_packets};
}

// Every payload accounted for, every channel slot a point or a filtered count, every point in a
// frame.
void check_accounting(const FaultOutcome& o) {
  CHECK(o.stats.packets == o.stats.accepted + o.stats.rejected() + o.stats.duplicates);
  CHECK(o.stats.points + o.stats.filtered.total() == o.stats.accepted * kSlots);
  CHECK(o.points_in_frames + o.frames.points_late + o.frames.points_dropped_full +
            o.frames.points_dropped_no_frame ==
        o.stats.points);
}

enum class Glitch {
  kTimeBack,        // 0.5 s behind
  kTimeForward,     // 0.5 s ahead
  kDateSecondBack,  // the date bytes still the second before
  kTimeYearsOff,    // a valid date, years back
  kZeroTime,        // date and microseconds zero
  kGarbageTime,     // a date and microseconds no clock writes
  kAzimuthAhead,    // +90°
  kAzimuthBehind,   // -45°
};
constexpr Glitch kGlitches[] = {
    Glitch::kTimeBack, Glitch::kTimeForward, Glitch::kDateSecondBack, Glitch::kTimeYearsOff,
    Glitch::kZeroTime, Glitch::kGarbageTime, Glitch::kAzimuthAhead,   Glitch::kAzimuthBehind};

const char* name(Glitch g) {
  switch (g) {
    case Glitch::kTimeBack:
      return "time 0.5 s back";
    case Glitch::kTimeForward:
      return "time 0.5 s forward";
    case Glitch::kDateSecondBack:
      return "date bytes a second back";
    case Glitch::kTimeYearsOff:
      return "time years back";
    case Glitch::kZeroTime:
      return "time zeroed";
    case Glitch::kGarbageTime:
      return "time garbage";
    case Glitch::kAzimuthAhead:
      return "azimuth +90°";
    case Glitch::kAzimuthBehind:
      return "azimuth -45°";
  }
  return "?";
}

void apply(Glitch g, std::span<std::uint8_t> packet, std::int64_t t_ns, std::uint32_t seed) {
  switch (g) {
    case Glitch::kTimeBack:
      test::set_time(packet, t_ns - 500 * kNsPerMillisecond);
      break;
    case Glitch::kTimeForward:
      test::set_time(packet, t_ns + 500 * kNsPerMillisecond);
      break;
    case Glitch::kDateSecondBack:
      test::date_second_back(packet);
      break;
    case Glitch::kTimeYearsOff:
      test::set_time(packet, t_ns - 7 * 365 * 86400 * 1'000'000'000LL);
      break;
    case Glitch::kZeroTime:
      test::zero_time(packet);
      break;
    case Glitch::kGarbageTime:
      test::garbage_time(packet, seed);
      break;
    case Glitch::kAzimuthAhead:
      test::shift_azimuth(packet, 9000);
      break;
    case Glitch::kAzimuthBehind:
      test::shift_azimuth(packet, -4500);
      break;
  }
}

constexpr ReturnMode kModes[] = {ReturnMode::kDual, ReturnMode::kLast, ReturnMode::kStrongest};

// The three streams, loaded once (each is the capture read and re-timed).
const RetimedCapture* stream_in(ReturnMode mode) {
  static const std::array<std::optional<RetimedCapture>, 3> streams = {
      RetimedCapture::load(ReturnMode::kDual), RetimedCapture::load(ReturnMode::kLast),
      RetimedCapture::load(ReturnMode::kStrongest)};
  const auto& s = streams[mode == ReturnMode::kDual ? 0 : mode == ReturnMode::kLast ? 1 : 2];
  return s ? &*s : nullptr;
}

// The burst lengths of the matrix. (Under the sanitizers, 1, 3 and 16 only: the same rule at
// a third of the time, which their CI job pays for every test.)
constexpr std::uint64_t kBurstLengths[] = {1, 2, 3, 5, 10, 16};

// Two seconds: 20 revolutions, bursts every 500 packets from packet 250.
std::uint64_t two_seconds(const RetimedCapture& s) {
  return 2 * s.packets_per_second();
}

}  // namespace

TEST_CASE(
    "a burst of 1 to 16 packets whose tail says another speed or return mode costs at most its "
    "packets",
    "[stream][faults]") {
  const RetimedCapture* stream = stream_in(ReturnMode::kDual);
  if (stream == nullptr) return;
  const std::uint64_t packets = two_seconds(*stream);
  const FaultOutcome clean = run_faults(*stream, packets, {});
  for (const std::uint64_t length : kBurstLengths) {
    const auto in_burst = [&](std::uint64_t k) { return k % 500 >= 250 && k % 500 < 250 + length; };
    // The tail's speed: the azimuth and the time say the stream goes on at 600 RPM.
    for (const std::uint16_t rpm : {std::uint16_t{0}, std::uint16_t{300}, std::uint16_t{1200}}) {
      INFO("bursts of " << length << ", tail " << rpm << " RPM");
      std::uint64_t glitched = 0;
      const FaultOutcome o =
          run_faults(*stream, packets, [&](std::uint64_t k, std::span<std::uint8_t> p) {
            if (in_burst(k)) {
              test::set_rpm(p, rpm);
              ++glitched;
            }
            return true;
          });
      check_accounting(o);
      CHECK(o.frames.discontinuities == 0);
      CHECK(o.stats.stream_changes == 0);
      CHECK(o.frames.frames_complete == clean.frames.frames_complete);
      CHECK(o.frames.frames_holed == 0);
      CHECK(o.frames.packets_missing == 0);
      // One alone is not the stream's speed: nothing held. Two or more in a row are taken for
      // it, and those that then do not follow are held and repaired (never more than the burst).
      CHECK(o.stats.outliers <= (length == 1 ? 0 : glitched));
    }
    // The return-mode byte: the stream is dual; the burst says last return.
    INFO("bursts of " << length << ", return mode byte");
    std::uint64_t glitched = 0;
    const FaultOutcome o =
        run_faults(*stream, packets, [&](std::uint64_t k, std::span<std::uint8_t> p) {
          if (in_burst(k)) {
            p[kBodyBytes + 14] = static_cast<std::uint8_t>(ReturnMode::kLast);
            ++glitched;
          }
          return true;
        });
    check_accounting(o);
    // Each decoded in the stream's mode (its byte mended), every point kept.
    CHECK(o.stats.outliers == glitched);
    CHECK(o.stats.filtered[FilterReason::kOutlier] == 0);
    CHECK(o.stats.points == clean.stats.points);
    CHECK(o.stats.return_mode_changes == 0);
    CHECK(o.frames.discontinuities == 0);
    CHECK(o.frames.frames_complete == clean.frames.frames_complete);
  }
  // 17 in a row in another mode are a change of mode, taken (and the 16 before it, outliers).
  const FaultOutcome change =
      run_faults(*stream, packets, [&](std::uint64_t k, std::span<std::uint8_t> p) {
        if (k >= 1000) p[kBodyBytes + 14] = static_cast<std::uint8_t>(ReturnMode::kLast);
        return true;
      });
  check_accounting(change);
  CHECK(change.stats.return_mode_changes == 1);
  CHECK(change.stats.outliers == kMaxHeldPackets);
  CHECK(change.stats.return_mode == ReturnMode::kLast);
}

TEST_CASE(
    "a burst of 1 to 16 glitched packets costs its packets, not a revolution, in every kind "
    "and return mode",
    "[stream][faults]") {
  for (const ReturnMode mode : kModes) {
    const RetimedCapture* stream = stream_in(mode);
    if (stream == nullptr) return;
    const std::uint64_t packets = two_seconds(*stream);
    const FaultOutcome clean = run_faults(*stream, packets, {});
    REQUIRE(clean.frames.frames_complete >= 18);
    REQUIRE(clean.frames.frames_holed == 0);
    REQUIRE(clean.stats.outliers == 0);
    for (const Glitch glitch : kGlitches) {
      for (const std::uint64_t length : kBurstLengths) {
        if (test::kSlowBuild && length != 1 && length != 3 && length != 16) continue;
        INFO(to_string(mode) << ": bursts of " << length << ", " << name(glitch));
        std::uint64_t glitched = 0;
        const FaultOutcome o =
            run_faults(*stream, packets, [&](std::uint64_t k, std::span<std::uint8_t> p) {
              if (k % 500 >= 250 && k % 500 < 250 + length) {
                apply(glitch, p, stream->time_ns(k), static_cast<std::uint32_t>(k));
                ++glitched;
              }
              return true;
            });
        check_accounting(o);
        CHECK(o.stats.outliers == glitched);
        CHECK(o.frames.discontinuities == 0);
        CHECK(o.frames.frames_holed == 0);
        // The goal is 95 %; the rule keeps them all.
        CHECK(o.frames.frames_complete == clean.frames.frames_complete);
        CHECK(o.frames.packets_missing == 0);
        // Each glitch's time named as what it was, against the stream.
        const bool back = glitch == Glitch::kTimeBack || glitch == Glitch::kDateSecondBack ||
                          glitch == Glitch::kTimeYearsOff;
        CHECK(o.stats.backward_timestamps == (back ? glitched : 0));
        CHECK(o.stats.timestamp_jumps == (glitch == Glitch::kTimeForward ? glitched : 0));
        const bool invalid = glitch == Glitch::kZeroTime || glitch == Glitch::kGarbageTime;
        CHECK(o.stats.bad_date + o.stats.bad_microseconds == (invalid ? glitched : 0));
        // Every one repaired and placed: its time re-derived from its azimuth, or its azimuth
        // from its time. None left out, every point kept.
        CHECK(o.stats.filtered[FilterReason::kOutlier] == 0);
        CHECK(o.stats.points == clean.stats.points);
      }
    }
  }
}

TEST_CASE(
    "glitch bursts' neighbours: at the cut, right after the start, with a loss, longer "
    "than 16",
    "[stream][faults]") {
  const RetimedCapture* stream = stream_in(ReturnMode::kDual);
  if (stream == nullptr) return;
  const std::uint64_t packets = two_seconds(*stream);
  const FaultOutcome clean = run_faults(*stream, packets, {});
  const auto crosses_cut = [&](std::uint64_t k) {
    std::array<std::uint8_t, kMaxPacketBytes> a{}, b{};
    const int before = test::first_azimuth(std::span(a).first(stream->packet(k - 1, a)));
    const int at = test::first_azimuth(std::span(b).first(stream->packet(k, b)));
    return at < before;  // wrapped past 0°, the cut
  };

  SECTION("at the cut") {
    for (const Glitch glitch : {Glitch::kTimeBack, Glitch::kAzimuthAhead, Glitch::kZeroTime}) {
      for (const std::uint64_t length : {1, 3, 16}) {
        INFO(name(glitch) << " x " << length << " starting at each crossing of the cut");
        std::uint64_t left = 0, glitched = 0;
        const FaultOutcome o =
            run_faults(*stream, packets, [&](std::uint64_t k, std::span<std::uint8_t> p) {
              // (Not in the last revolution: a run the stream ends in is placed as it is.)
              if (k > 0 && k + 360 < packets && crosses_cut(k)) left = length;
              if (left == 0) return true;
              --left;
              ++glitched;
              apply(glitch, p, stream->time_ns(k), static_cast<std::uint32_t>(k));
              return true;
            });
        check_accounting(o);
        CHECK(glitched >= 19 * length);
        CHECK(o.stats.outliers == glitched);
        CHECK(o.frames.frames_complete == clean.frames.frames_complete);
        CHECK(o.frames.discontinuities == 0);
      }
    }
  }
  SECTION("right after the start") {
    for (const Glitch glitch : {Glitch::kTimeForward, Glitch::kAzimuthBehind}) {
      for (const std::uint64_t length : {1, 5, 16}) {
        INFO(name(glitch) << " x " << length << " first");
        const FaultOutcome o =
            run_faults(*stream, packets, [&](std::uint64_t k, std::span<std::uint8_t> p) {
              if (k < length) apply(glitch, p, stream->time_ns(k), 0);
              return true;
            });
        check_accounting(o);
        CHECK(o.stats.outliers == length);
        CHECK(o.frames.frames_complete == clean.frames.frames_complete);
        CHECK(o.frames.discontinuities == 0);
      }
    }
  }
  SECTION("a burst, then a loss: only the loss costs the revolution") {
    std::uint64_t bursts = 0, events = 0;
    const FaultOutcome o =
        run_faults(*stream, packets, [&](std::uint64_t k, std::span<std::uint8_t> p) {
          const std::uint64_t at = k % 720;  // two revolutions apart, mid-revolution
          if (at >= 180 && at < 183) apply(Glitch::kTimeBack, p, stream->time_ns(k), 0);
          if (at == 183) {
            ++bursts;
            if (k > 360) ++events;  // (the first frame is partial anyway: the stream began in it)
          }
          return at < 183 || at >= 188;  // 5 lost right after it
        });
    check_accounting(o);
    CHECK(o.stats.outliers == 3 * bursts);
    CHECK(o.frames.frames_holed == events);
    CHECK(o.frames.frames_complete == clean.frames.frames_complete - events);
    CHECK(o.frames.packets_missing == 5 * bursts);
  }
  SECTION("17 and more that follow each other are a change: taken, cut, and taken back") {
    for (const Glitch glitch : {Glitch::kTimeBack, Glitch::kTimeForward, Glitch::kAzimuthAhead}) {
      for (const std::uint64_t length : {17, 20, 40}) {
        INFO(name(glitch) << " x " << length);
        const FaultOutcome o =
            run_faults(*stream, packets, [&](std::uint64_t k, std::span<std::uint8_t> p) {
              if (k % 1000 >= 400 && k % 1000 < 400 + length) {
                apply(glitch, p, stream->time_ns(k), 0);
              }
              return true;
            });
        check_accounting(o);
        // Each run is a new stream and the old one's return another: two cuts, no outlier.
        CHECK(o.frames.discontinuities == 2 * 7);
        CHECK(o.stats.outliers == 0);
        CHECK(o.stats.points == clean.stats.points);
        // A change costs the revolutions it cut (each run and its return): at most three.
        CHECK(o.frames.frames_complete + 3 * 7 >= clean.frames.frames_complete);
      }
    }
  }
  SECTION("17 and more that do not follow each other are still a glitch") {
    for (const std::uint64_t length : {17, 30}) {
      INFO("scattered azimuths x " << length);
      std::uint64_t glitched = 0, events = 0;
      const FaultOutcome o =
          run_faults(*stream, packets, [&](std::uint64_t k, std::span<std::uint8_t> p) {
            if (k % 1000 >= 400 && k % 1000 < 400 + length) {
              test::shift_azimuth(p, 9000 + static_cast<int>(k % 2) * 18000);
              ++glitched;
              if (k % 1000 == 400) ++events;
            }
            return true;
          });
      check_accounting(o);
      CHECK(o.stats.outliers == glitched);
      CHECK(o.frames.discontinuities == 0);
      // The last 16 held are repaired from their times; the ones before them were let go as
      // strays while the run went on: left out, and their revolutions partial (not lost).
      CHECK(o.stats.filtered[FilterReason::kOutlier] == events * (length - 16) * kSlots);
      CHECK(o.frames.frames_complete == clean.frames.frames_complete - events);
      CHECK(o.frames.packets_missing == 0);
    }
  }
}

TEST_CASE(
    "complete means complete: a loss of 1 to 500 packets makes its revolutions partial and "
    "is counted in packets",
    "[stream][faults]") {
  for (const ReturnMode mode : kModes) {
    const RetimedCapture* stream = stream_in(mode);
    if (stream == nullptr) return;
    const std::uint64_t packets = 3 * stream->packets_per_second();
    const std::uint64_t revolution = stream->packets_per_second() / 10;
    const FaultOutcome clean = run_faults(*stream, packets, {});
    for (const std::uint64_t lost : {1, 5, 50}) {
      for (const bool sequence : {false, true}) {
        INFO(to_string(mode) << ": " << lost << " lost every other revolution, mid-revolution"
                             << (sequence ? ", with the UDP sequence" : ""));
        std::uint64_t events = 0;
        // From the second revolution to the third-last (the first frame and the last are
        // partial whatever they lose).
        const auto lossy = [&](std::uint64_t k) {
          return k > revolution && k + 3 * revolution < packets;
        };
        const FaultOutcome o = run_faults(
            *stream, packets,
            [&](std::uint64_t k, std::span<std::uint8_t>) {
              const std::uint64_t at = (k + revolution / 2) % (2 * revolution);
              if (at == 0 && lossy(k)) ++events;
              return !lossy(k) || at >= lost;
            },
            sequence);
        check_accounting(o);
        CHECK(events >= 12);
        const bool hole =
            static_cast<double>(lost) * azimuth_step_per_packet_cdeg(mode, 600) < 9000;
        // Counted by the sequence when there is one; else by the azimuth the frames lacked, which
        // a loss wider than 90° is not (a discontinuity: a restart looks the same).
        CHECK(packets_missing(o.stats, o.sequence, o.frames) ==
              (sequence || hole ? lost * events : 0));
        if (hole) {
          // A hole in the revolution: that frame partial, no other.
          CHECK(o.frames.frames_holed == events);
          CHECK(o.frames.packets_missing == lost * events);
          CHECK(o.frames.frames_complete == clean.frames.frames_complete - events);
          CHECK(o.frames.frames_complete + o.frames.frames_partial ==
                clean.frames.frames_complete + clean.frames.frames_partial);
          CHECK(o.frames.discontinuities == 0);
        } else {
          // More than 90° of azimuth (50 single-return packets): a discontinuity, the frame it
          // ends and the one it starts partial.
          CHECK(o.frames.discontinuities == events);
          CHECK(o.frames.frames_complete >= clean.frames.frames_complete - 2 * events);
          CHECK(o.frames.frames_complete < clean.frames.frames_complete);
        }
      }
    }
    {
      INFO(to_string(mode) << ": 500 lost (more than a revolution) twice");
      const auto lose = [&](std::uint64_t k, std::span<std::uint8_t>) {
        return !(k >= revolution * 10 && k < revolution * 10 + 500) &&
               !(k >= revolution * 20 && k < revolution * 20 + 500);
      };
      const FaultOutcome o = run_faults(*stream, packets, lose);
      check_accounting(o);
      CHECK(o.frames.discontinuities == 2);
      // Without a sequence, nothing can tell so long a loss from a restart or a clock's step.
      CHECK(packets_missing(o.stats, o.sequence, o.frames) == 0);
      CHECK(packets_missing(run_faults(*stream, packets, lose, true).stats,
                            run_faults(*stream, packets, lose, true).sequence,
                            run_faults(*stream, packets, lose, true).frames) == 1000);
      // The revolutions the loss spans, and those it cut on either side.
      const std::uint64_t spanned = 2 * (500 / revolution + 2);
      CHECK(o.frames.frames_complete + spanned >= clean.frames.frames_complete);
      CHECK(o.frames.frames_complete < clean.frames.frames_complete);
    }
    for (const std::uint64_t lost : {1, 5}) {
      INFO(to_string(mode) << ": " << lost << " lost at each crossing of the cut");
      int previous = -1;
      std::uint64_t left = 0, events = 0;
      const FaultOutcome o =
          run_faults(*stream, packets, [&](std::uint64_t k, std::span<std::uint8_t> p) {
            const int azimuth = test::first_azimuth(p);
            // (Not where the stream ends within the loss: no packet after it says how wide it was.)
            if (previous >= 0 && azimuth < previous && k + lost < packets) {
              left = lost;
              ++events;
            }
            previous = azimuth;
            if (left == 0) return true;
            --left;
            return false;
          });
      check_accounting(o);
      // Both revolutions lose points: the one it ends (channels reach past the cut) and the
      // one it starts.
      CHECK(o.frames.frames_complete == 0);
      CHECK(o.frames.packets_missing == lost * events);
    }
  }
}

TEST_CASE(
    "a motor that stands: its packets counted and left out, no frame piled up, whatever "
    "the tail says",
    "[stream][faults]") {
  for (const ReturnMode mode : {ReturnMode::kDual, ReturnMode::kLast}) {
    const RetimedCapture* stream = stream_in(mode);
    if (stream == nullptr) return;
    const std::uint64_t rate = stream->packets_per_second();
    for (const double seconds : {0.2, 2.0, 10.0}) {
      for (const bool tail_zero : {true, false}) {
        INFO(to_string(mode) << ": standing " << seconds << " s, tail "
                             << (tail_zero ? "0 RPM" : "600 RPM"));
        // 1 s turning, then standing at the azimuth it had, then 1 s turning again from where
        // the capture's packets are by then.
        const auto stand_from = rate;
        const auto stand_to =
            stand_from + static_cast<std::uint64_t>(seconds * static_cast<double>(rate));
        int stood_at = 0;
        const FaultOutcome o =
            run_faults(*stream, stand_to + rate, [&](std::uint64_t k, std::span<std::uint8_t> p) {
              if (k == stand_from) stood_at = test::first_azimuth(p);
              if (k >= stand_from && k < stand_to) {
                test::set_azimuth(p, stood_at);
                if (tail_zero) test::set_rpm(p, 0);
              }
              return true;
            });
        check_accounting(o);
        // The first standing packet still has its own azimuth's neighbour before it.
        CHECK(o.stats.standing + 1 >= stand_to - stand_from);
        CHECK(o.stats.standing <= stand_to - stand_from);
        CHECK(o.stats.filtered[FilterReason::kStanding] == o.stats.standing * kSlots);
        // Turning again is a change whose clock went on with the standing packets: no leap.
        CHECK(o.stats.timestamp_jumps == 0);
        CHECK(o.stats.backward_timestamps == 0);
        // No frame holds more than a revolution and a quarter, and none overflowed.
        CHECK(o.most_packets <= 1.25 * packets_per_revolution(mode, 598));
        CHECK(o.frames.points_dropped_full == 0);
        // Frames stopped closing while it stood (three revolutions' worth on)...
        if (seconds >= 2) CHECK(o.stats.frameless_packets > 0);
        // ... and turning again, the stream is cut and revolutions are whole again.
        CHECK(o.frames.discontinuities >= 1);
        CHECK(o.frames.frames_complete >= 2 * 10 - 4);
        // The measured speed stood too: 0 RPM over the standing packets.
        CHECK(o.stats.measured_time_ns >=
              static_cast<std::uint64_t>(seconds * 0.9 * 1e9) + 1'500'000'000ULL);
      }
    }
  }
  SECTION("crawling: the tail says 600, the azimuth turns a tenth of that") {
    const RetimedCapture* stream = stream_in(ReturnMode::kDual);
    if (stream == nullptr) return;
    const FaultOutcome o =
        run_faults(*stream, 3600, [&](std::uint64_t k, std::span<std::uint8_t> p) {
          const int base = static_cast<int>(k * 10 % 36000);  // 0.1° a packet
          for (int b = 0; b < kBlocks; ++b) {
            const int azimuth = (base + 2 * (b / 2)) % 36000;
            p[static_cast<std::size_t>(kBlockBytes * b + 2)] = static_cast<std::uint8_t>(azimuth);
            p[static_cast<std::size_t>(kBlockBytes * b + 3)] =
                static_cast<std::uint8_t>(azimuth >> 8);
          }
          return true;
        });
    check_accounting(o);
    // (The tail's slowest, 598 RPM, sets the bound: 451 packets.)
    CHECK(o.most_packets <= 1.25 * packets_per_revolution(ReturnMode::kDual, 598));
    // No packet follows the one before at the tail's speed: each is an outlier, none placed, and
    // frames stop closing within three revolutions' worth (the health's "motor stopped").
    CHECK(o.stats.outliers + kMaxHeldPackets >= 3600);
    CHECK(o.stats.frameless_packets >= 3600 - 3 * 400);
    CHECK(o.frames.frames_complete == 0);
    CHECK(o.frames.points_dropped_full == 0);
    const double measured = (static_cast<double>(o.stats.measured_azimuth_cdeg) / 36000.0) /
                            (static_cast<double>(o.stats.measured_time_ns) / 60e9);
    CHECK(measured == Approx(60).margin(1));
  }
}

TEST_CASE(
    "a stream that turns backwards is a change, taken within 17 packets: its packets counted "
    "and filtered as reversed, no frame cut from them, and turning forwards again is a change back",
    "[stream][faults]") {
  for (const ReturnMode mode : {ReturnMode::kDual, ReturnMode::kLast}) {
    const RetimedCapture* stream = stream_in(mode);
    if (stream == nullptr) return;
    const std::uint64_t rate = stream->packets_per_second();
    for (const std::uint64_t from : {rate, rate + rate / 7}) {
      for (const bool back_again : {false, true}) {
        INFO(to_string(mode) << ": reversed from packet " << from
                             << (back_again ? ", forwards again after 1 s" : ""));
        const std::uint64_t until = back_again ? from + rate : 3 * rate;
        int pivot = 0;
        const FaultOutcome o =
            run_faults(*stream, 3 * rate, [&](std::uint64_t k, std::span<std::uint8_t> p) {
              if (k == from) pivot = test::first_azimuth(p);
              if (k < from || k >= until) return true;
              // Mirrored about the azimuth where it turned: the rotation runs down.
              for (int b = 0; b < kBlocks; ++b) {
                const auto at = static_cast<std::size_t>(kBlockBytes * b + 2);
                const int azimuth = p[at] | (p[at + 1] << 8);
                const int mirrored = ((2 * pivot - azimuth) % 36000 + 36000) % 36000;
                p[at] = static_cast<std::uint8_t>(mirrored);
                p[at + 1] = static_cast<std::uint8_t>(mirrored >> 8);
              }
              return true;
            });
        // Every slot a point or a filtered count, the reversed ones too.
        check_accounting(o);
        const std::uint64_t reversed = until - from;
        // (Its first packet is where the stream was: it still follows.)
        CHECK(o.stats.reversed + 1 >= reversed);
        CHECK(o.stats.reversed <= reversed);
        CHECK(o.stats.filtered[FilterReason::kReversed] == o.stats.reversed * kSlots);
        CHECK(o.stats.outliers == 0);
        CHECK(o.stats.stream_changes == (back_again ? 2 : 1));
        // The frames before it whole; none cut while it ran backwards (at most a revolution's
        // packets in any); after it turned forwards again, whole ones again.
        CHECK(o.most_packets <= frame_packet_limit(mode, 602, 830));
        CHECK(o.frames.frames_complete >= (back_again ? 2 * 10 - 4 : 10 - 2));
        CHECK(o.frames.frames_complete <= (back_again ? 2 * 10 : 10));
      }
    }
  }
}

TEST_CASE("a sensor that restarts its counter at any moment is a reset: every packet decoded",
          "[stream][faults]") {
  const RetimedCapture* stream = stream_in(ReturnMode::kDual);
  if (stream == nullptr) return;
  struct Case {
    const char* name;
    std::uint32_t first;                 // the stream's first number
    std::vector<std::uint64_t> reboots;  // packets at which the counter restarts at `restart`
    std::uint32_t restart;
  };
  const Case cases[] = {
      {"at 720 of a stream from 0, to 0", 0, {720}, 0},
      {"at 100 of a stream from 0, to 1", 0, {100}, 1},
      {"at 1023 and 1024", 0, {1023, 1024}, 0},
      {"twice within 1024", 5000, {300, 900}, 0},
      {"at 5000", 0, {5000}, 0},
      {"near 2^32, to 0 (ahead by 16)", 0xFFFFFFE0, {16}, 0},
      {"to a number ahead of the stream", 0, {2000}, 2500},
  };
  for (const Case& c : cases) {
    INFO(c.name);
    const FaultOutcome o = run_faults(
        *stream, 7200,
        [&](std::uint64_t k, std::span<std::uint8_t> p) {
          std::uint32_t number = c.first + static_cast<std::uint32_t>(k);
          for (const std::uint64_t at : c.reboots) {
            if (k >= at) number = c.restart + static_cast<std::uint32_t>(k - at);
          }
          p[kPacketBytes] = static_cast<std::uint8_t>(number);
          p[kPacketBytes + 1] = static_cast<std::uint8_t>(number >> 8);
          p[kPacketBytes + 2] = static_cast<std::uint8_t>(number >> 16);
          p[kPacketBytes + 3] = static_cast<std::uint8_t>(number >> 24);
          return true;
        },
        true);
    check_accounting(o);
    CHECK(o.stats.accepted == 7200);
    CHECK(o.stats.duplicates == 0);
    CHECK(o.sequence.resets == c.reboots.size());
    CHECK(o.sequence.lost == 0);
    CHECK(o.frames.frames_holed == 0);
  }
  SECTION("a restart in a burst of glitched times: a reset, and the burst outliers") {
    const FaultOutcome o = run_faults(
        *stream, 7200,
        [&](std::uint64_t k, std::span<std::uint8_t> p) {
          const auto number = static_cast<std::uint32_t>(k < 700 ? k : k - 700);
          std::memcpy(p.data() + kPacketBytes, &number, 4);
          if (k >= 699 && k < 702) apply(Glitch::kTimeBack, p, stream->time_ns(k), 0);
          return true;
        },
        true);
    check_accounting(o);
    CHECK(o.stats.accepted == 7200);
    CHECK(o.sequence.resets == 1);
    CHECK(o.stats.outliers == 3);
  }
  SECTION("what is a copy stays a copy, a late packet a reordered one") {
    // A copy 200 packets late (outside the byte window) with its own time, and a packet held
    // back three places: by the numbers and the time, a duplicate and a reordered one.
    FrameTally tally;
    StreamDecoder decoder(Calibration::nominal(), {}, tally);
    std::array<std::uint8_t, kMaxPacketBytes> buffer{};
    std::vector<std::vector<std::uint8_t>> sent;
    for (std::uint64_t k = 0; k < 1500; ++k) {
      const auto bytes = std::span(buffer).first(stream->packet(k, buffer, std::uint32_t(k)));
      sent.emplace_back(bytes.begin(), bytes.end());
    }
    for (std::uint64_t k = 0; k < 1500; ++k) {
      if (k == 1001) continue;
      decoder.process(sent[k]);
      if (k == 1003) decoder.process(sent[1001]);
      if (k == 1300) decoder.process(sent[1100]);
    }
    decoder.flush();
    CHECK(decoder.sequence().resets == 0);
    CHECK(decoder.sequence().reordered == 1);
    CHECK(decoder.sequence().duplicates == 1);
    CHECK(decoder.stats().duplicates == 1);
    CHECK(decoder.sequence().lost == 0);
  }
}

TEST_CASE("two streams merged on one port: twice the sensor's packet rate by its clock",
          "[stream][faults]") {
  const RetimedCapture* stream = stream_in(ReturnMode::kDual);
  if (stream == nullptr) return;
  FrameTally tally;
  for (const int offset_cdeg : {0, 18000}) {
    INFO("a second sensor, phase-locked, " << offset_cdeg / 100 << "° apart");
    StreamDecoder decoder(Calibration::nominal(), {}, tally);
    std::array<std::uint8_t, kMaxPacketBytes> a{}, b{};
    for (std::uint64_t k = 0; k < 3600; ++k) {
      const auto first = std::span(a).first(stream->packet(k, a));
      const auto second = std::span(b).first(stream->packet(k + 700, b));
      test::set_time(second, stream->time_ns(k));
      test::shift_azimuth(second,
                          offset_cdeg - (test::first_azimuth(second) - test::first_azimuth(first)));
      decoder.process(first);
      decoder.process(second);
    }
    decoder.flush();
    const StreamStats& s = decoder.stats();
    const double rate =
        static_cast<double>(s.rate_packets) * 1e9 / static_cast<double>(s.rate_time_ns);
    CHECK(rate == Approx(7200).epsilon(0.02));
  }
  StreamDecoder alone(Calibration::nominal(), {}, tally);
  std::array<std::uint8_t, kMaxPacketBytes> buffer{};
  for (std::uint64_t k = 0; k < 3600; ++k)
    alone.process(std::span(buffer).first(stream->packet(k, buffer)));
  const StreamStats& s = alone.stats();
  CHECK(static_cast<double>(s.rate_packets) * 1e9 / static_cast<double>(s.rate_time_ns) ==
        Approx(3600).epsilon(0.01));
}
