// A glitch costs a packet, not a revolution (core/decode/stream_decoder.hpp): the rule that tells
// an isolated outlier from a real change, at its boundaries; duplicates decoded once; and streams
// with a glitch every few hundred packets cut into as many whole revolutions as clean ones.
#include <array>
#include <catch2/catch.hpp>
#include <cstdint>
#include <functional>
#include <random>
#include <tuple>
#include <vector>

#include "core/decode/calibration.hpp"
#include "core/decode/packet_time.hpp"
#include "core/decode/stream_decoder.hpp"
#include "core/frames/frame_collector.hpp"
#include "core/sensors/timing.hpp"
#include "core/sim/packet_builder.hpp"
#include "core/sim/synthetic_sensor.hpp"
#include "core/units.hpp"

using namespace pandarcap;

namespace {

// 600 RPM: 36000 cdeg per 100 ms, 0.36 cdeg per µs.
constexpr std::int64_t kRevolutionNs = 100 * kNsPerMillisecond;

RotationPoint packet_at(int azimuth_cdeg, std::int64_t t0_ns, bool valid = true, int rpm = 600) {
  return {static_cast<std::uint16_t>(((azimuth_cdeg % 36000) + 36000) % 36000), t0_ns, valid,
          static_cast<std::uint16_t>(rpm)};
}

// A stream of the simulated sensor whose packets `alter` may change (their contents) or drop
// (return false), fed to a StreamDecoder: its counters and whole frames.
struct GlitchOutcome {
  StreamStats stats;
  AssemblerStats frames;
  std::uint64_t points_in_frames = 0;
};
GlitchOutcome run_glitches(int packets, const std::function<bool(int, PacketContents&)>& alter,
                           SyntheticSensorConfig config = {}) {
  SyntheticSensor sensor(config);
  std::uint64_t points = 0;
  FrameCollector frames(3, kDefaultFrameCapacityPoints,
                        [&](const Frame& frame) { points += frame.size; });
  StreamDecoder decoder(Calibration::nominal(), {}, frames);
  std::array<std::uint8_t, kMaxPacketBytes> buffer{};
  for (int k = 0; k < packets; ++k) {
    PacketContents contents = sensor.next_contents();
    if (!alter(k, contents)) continue;
    const std::size_t size = encode(contents, buffer);
    REQUIRE(decoder.process(std::span(buffer).first(size)) == RejectReason::kNone);
  }
  decoder.flush();
  return {decoder.stats(), decoder.frames(), points};
}

// Moves the packet's tail time by `shift_ns` (its UTC date-time and µs field).
void shift_time(PacketContents& contents, std::int64_t shift_ns) {
  PacketClock clock;
  const PacketTime time = clock.convert(contents.tail.utc, contents.tail.timestamp_us);
  const std::int64_t t = time.t0_ns + shift_ns;
  contents.tail.utc = tail_datetime_from_unix(t / 1'000'000'000);
  contents.tail.timestamp_us = static_cast<std::uint32_t>((t % 1'000'000'000) / 1000);
}

void shift_azimuth(PacketContents& contents, int shift_cdeg) {
  for (auto& azimuth : contents.azimuth_cdeg)
    azimuth = static_cast<std::uint16_t>((azimuth + shift_cdeg + 36000) % 36000);
}

const auto kClean = [](int, PacketContents&) { return true; };

}  // namespace

TEST_CASE(
    "follows: a packet follows when its azimuth advanced as its time did, within 0.2° + 1 %, "
    "either way round",
    "[stream][glitch]") {
  const RotationPoint last = packet_at(10000, 0);
  // 10 ms at 600 RPM is 36°: 3600 cdeg, tolerance 20 + 36 cdeg.
  CHECK(follows(last, packet_at(10000 + 3600, 10 * kNsPerMillisecond)));
  CHECK(follows(last, packet_at(10000 + 3600 + 56, 10 * kNsPerMillisecond)));
  CHECK_FALSE(follows(last, packet_at(10000 + 3600 + 57, 10 * kNsPerMillisecond)));
  CHECK(follows(last, packet_at(10000 + 3600 - 56, 10 * kNsPerMillisecond)));
  CHECK_FALSE(follows(last, packet_at(10000 + 3600 - 57, 10 * kNsPerMillisecond)));
  // One dual packet (277.8 µs, 1°): 0.21° either side; a packet shifted by 0.25° does not.
  CHECK(follows(last, packet_at(10000 + 100 + 21, 277'800)));
  CHECK_FALSE(follows(last, packet_at(10000 + 100 + 25, 277'800)));
  CHECK_FALSE(follows(last, packet_at(10000 + 100 - 25, 277'800)));
  CHECK_FALSE(follows(last, packet_at(10000 + 100 + 100, 277'800)));  // 1° ahead
  // A swapped pair: time and azimuth both a packet back.
  CHECK(follows(last, packet_at(10000 - 100, -277'800)));
  // Half a revolution of time, even with the azimuth that goes with it, is a gap.
  CHECK(follows(last, packet_at(10000 + 18000 - 36, kRevolutionNs / 2 - 100'000)));
  CHECK_FALSE(follows(last, packet_at(10000 + 18000, kRevolutionNs / 2 + 1)));
  CHECK_FALSE(follows(last, packet_at(10000, kRevolutionNs)));  // a whole revolution lost
  // The speed is the last packet's: at 1200 RPM 10 ms is 72°.
  CHECK(follows(packet_at(0, 0, true, 1200), packet_at(7200, 10 * kNsPerMillisecond)));
  CHECK_FALSE(follows(packet_at(0, 0, true, 600), packet_at(7200, 10 * kNsPerMillisecond)));
  // Backwards: the azimuth goes back as the time goes on.
  CHECK(follows(last, packet_at(10000 - 100, 277'800), Turning::kBackward));
  CHECK_FALSE(follows(last, packet_at(10000 - 100, 277'800)));
  CHECK_FALSE(follows(last, packet_at(10000 + 100, 277'800), Turning::kBackward));
}

TEST_CASE("follows: without usable times, a step of at most 90° either way", "[stream][glitch]") {
  for (const auto& [last, valid, name] :
       {std::tuple{packet_at(5000, 0, false), false, "invalid times"},
        std::tuple{packet_at(5000, 0, true, 0), true, "no speed"}}) {
    INFO(name);
    CHECK(follows(last, packet_at(5000 + 9000, kNsPerMillisecond, valid)));
    CHECK_FALSE(follows(last, packet_at(5000 + 9001, kNsPerMillisecond, valid)));
    CHECK(follows(last, packet_at(5000 - 9000, kNsPerMillisecond, valid)));
    CHECK_FALSE(follows(last, packet_at(5000 - 9001, kNsPerMillisecond, valid)));
  }
  // A valid time after an invalid one, or the reverse: two clocks, never "follows".
  CHECK_FALSE(follows(packet_at(5000, 0, true), packet_at(5100, 277'800, false)));
  CHECK_FALSE(follows(packet_at(5000, 0, false), packet_at(5100, 277'800, true)));
  // A frozen clock (the same time, or a packet whose time stood): the azimuth alone, too.
  CHECK(follows(packet_at(5000, 7 * kNsPerMillisecond),
                packet_at(5000 + 4000, 7 * kNsPerMillisecond)));
  CHECK_FALSE(follows(packet_at(5000, 7 * kNsPerMillisecond),
                      packet_at(5000 + 9500, 7 * kNsPerMillisecond)));
  RotationPoint stood = packet_at(5000, 7 * kNsPerMillisecond);
  stood.time_stood = true;
  CHECK(follows(stood, packet_at(5100, 10 * kNsPerMillisecond)));
  CHECK_FALSE(
      follows(packet_at(5000, 7 * kNsPerMillisecond), packet_at(5100, 10 * kNsPerMillisecond)));
}

TEST_CASE("an isolated time glitch is placed at its azimuth's time: no frame or point lost",
          "[stream][glitch]") {
  const GlitchOutcome clean = run_glitches(7200, kClean);
  REQUIRE(clean.frames.frames_complete >= 18);
  for (const std::int64_t shift : {-5 * kNsPerMillisecond, -2000 * kNsPerMillisecond,
                                   60'000 * kNsPerMillisecond, 20 * kNsPerMillisecond}) {
    INFO("packet 3000's time moved by " << shift / kNsPerMillisecond << " ms");
    const GlitchOutcome glitch = run_glitches(7200, [&](int k, PacketContents& c) {
      if (k == 3000) shift_time(c, shift);
      return true;
    });
    CHECK(glitch.stats.outliers == 1);
    CHECK(glitch.frames.discontinuities == 0);
    CHECK(glitch.frames.frames_complete == clean.frames.frames_complete);
    CHECK(glitch.frames.frames_partial == clean.frames.frames_partial);
    CHECK(glitch.stats.points == clean.stats.points);
    CHECK(glitch.points_in_frames == clean.points_in_frames);
    CHECK(glitch.stats.filtered[FilterReason::kOutlier] == 0);
  }
}

TEST_CASE(
    "an isolated azimuth glitch is repaired from its time: its points kept, the revolution "
    "whole (one wrong in both is left out, its revolution partial)",
    "[stream][glitch]") {
  const GlitchOutcome clean = run_glitches(7200, kClean);
  for (const int shift : {18000, 9500, -12000, 3000, 100, -100, 25}) {
    INFO("packet 3000's azimuths moved by " << shift << " cdeg");
    const GlitchOutcome glitch = run_glitches(7200, [&](int k, PacketContents& c) {
      if (k == 3000) shift_azimuth(c, shift);
      return true;
    });
    CHECK(glitch.stats.outliers == 1);
    CHECK(glitch.stats.filtered[FilterReason::kOutlier] == 0);
    CHECK(glitch.stats.points == clean.stats.points);
    CHECK(glitch.points_in_frames == clean.points_in_frames);
    CHECK(glitch.frames.discontinuities == 0);
    CHECK(glitch.frames.frames_complete == clean.frames.frames_complete);
    CHECK(glitch.frames.packets_missing == 0);
  }
  for (const int shift : {18000, 100}) {
    INFO("packet 3000's azimuths moved by " << shift << " cdeg and its time 2 ms back");
    const GlitchOutcome glitch = run_glitches(7200, [&](int k, PacketContents& c) {
      if (k == 3000) {
        shift_azimuth(c, shift);
        shift_time(c, -2 * kNsPerMillisecond);
      }
      return true;
    });
    CHECK(glitch.stats.outliers == 1);
    CHECK(glitch.stats.filtered[FilterReason::kOutlier] == kBlocks * kChannels);
    CHECK(glitch.frames.discontinuities == 0);
    // Its revolution lacks its points: partial, though nothing was lost.
    CHECK(glitch.frames.frames_complete + 1 == clean.frames.frames_complete);
    CHECK(glitch.frames.frames_holed == 1);
    CHECK(glitch.frames.packets_missing == 0);
    // Every slot of every accepted packet is a point or a filtered count.
    CHECK(glitch.stats.points + glitch.stats.filtered.total() ==
          glitch.stats.accepted * kBlocks * kChannels);
  }
}

TEST_CASE("two glitches in a row are two outliers, and a real change still cuts",
          "[stream][glitch]") {
  const GlitchOutcome clean = run_glitches(7200, kClean);
  const GlitchOutcome twice = run_glitches(7200, [](int k, PacketContents& c) {
    if (k == 3000) shift_azimuth(c, 18000);
    if (k == 3001) shift_azimuth(c, 9000);
    return true;
  });
  CHECK(twice.stats.outliers == 2);
  CHECK(twice.frames.discontinuities == 0);
  CHECK(twice.frames.frames_complete == clean.frames.frames_complete);

  // A restart: from packet 3000 on, the sensor is 137° and 3 s further on. It cuts once, and
  // nothing is taken for an outlier.
  const GlitchOutcome restart = run_glitches(7200, [](int k, PacketContents& c) {
    if (k >= 3000) {
      shift_azimuth(c, 13700);
      shift_time(c, 3000 * kNsPerMillisecond);
    }
    return true;
  });
  CHECK(restart.stats.outliers == 0);
  CHECK(restart.frames.discontinuities == 1);
  CHECK(restart.stats.points == clean.stats.points);

  // A gap: a revolution and a half of packets missing. The azimuth follows the time, but the time
  // is more than half a revolution: it cuts.
  const GlitchOutcome gap =
      run_glitches(7200, [](int k, PacketContents&) { return k < 3000 || k >= 3540; });
  CHECK(gap.stats.outliers == 0);
  CHECK(gap.frames.discontinuities == 1);

  // A real change of speed: 600 RPM, then the same stream at 1200 RPM from where it was.
  SyntheticSensor slow(SyntheticSensorConfig{});
  FrameCollector frames(3, kDefaultFrameCapacityPoints, [](const Frame&) {});
  StreamDecoder decoder(Calibration::nominal(), {}, frames);
  std::array<std::uint8_t, kMaxPacketBytes> buffer{};
  for (int k = 0; k < 3600; ++k)
    decoder.process(std::span(buffer).first(slow.next(buffer)));
  SyntheticSensorConfig fast_config;
  fast_config.rpm = 1200;
  // Its first packet a period after the slow one's last (t0 comes 4 rounds and 28.58 µs after a
  // dual packet's first firing).
  fast_config.start_unix_ns = slow.last_packet_time_ns() + kRoundPeriodNs - kLastRoundEndNs;
  // The next packet's first azimuth at 600 RPM: where the slow stream's next one would start.
  fast_config.start_azimuth_deg =
      (PacketView::assume_valid(std::span(buffer).first(kPacketBytes)).azimuth_cdeg(0) + 100) /
      100.0;
  SyntheticSensor fast(fast_config);
  for (int k = 0; k < 3600; ++k)
    decoder.process(std::span(buffer).first(fast.next(buffer)));
  decoder.flush();
  CHECK(decoder.stats().outliers == 0);
  CHECK(decoder.frames().discontinuities == 0);
}

TEST_CASE("duplicates: a copy of a recent packet, or a repeated sequence, is decoded once",
          "[stream][glitch][duplicate]") {
  SyntheticSensorConfig config;
  config.udp_sequence = true;
  const GlitchOutcome clean = run_glitches(3600, kClean, config);

  SyntheticSensor sensor(config);
  FrameCollector frames(3, kDefaultFrameCapacityPoints, [](const Frame&) {});
  StreamDecoder decoder(Calibration::nominal(), {}, frames);
  std::vector<std::vector<std::uint8_t>> sent;
  std::array<std::uint8_t, kMaxPacketBytes> buffer{};
  std::uint64_t copies = 0;
  for (int k = 0; k < 3600; ++k) {
    const std::size_t size = sensor.next(buffer);
    sent.emplace_back(buffer.begin(), buffer.begin() + static_cast<long>(size));
    REQUIRE(decoder.process(sent.back()) == RejectReason::kNone);
    // A switch loop: every 100th packet twice, at once.
    if (k % 100 == 50) {
      decoder.process(sent.back());
      ++copies;
    }
    // A mirror port's late copy, 40 packets later (inside the window).
    if (k % 500 == 499) {
      decoder.process(sent[sent.size() - 41]);
      ++copies;
    }
    // A repeated sequence number with other bytes (another sender, a firmware bug).
    if (k == 2000) {
      std::vector<std::uint8_t> other = sent[sent.size() - 3];
      other[100] ^= 0x5A;  // a distance byte
      decoder.process(other);
      ++copies;
    }
  }
  decoder.flush();
  const StreamStats& s = decoder.stats();
  CHECK(s.duplicates == copies);
  CHECK(s.accepted == 3600);
  CHECK(s.packets == s.accepted + s.rejected() + s.duplicates);
  CHECK(s.points == clean.stats.points);
  CHECK(decoder.frames().frames_complete == clean.frames.frames_complete);
  CHECK(s.static_timestamps == 0);  // a copy is not taken for a clock that stood still
  CHECK(s.outliers == 0);

  // Without a sequence, a copy older than the window is a packet like any other: decoded, a late
  // packet to the frame assembler (its time and azimuth agree: not an outlier).
  SyntheticSensor plain(SyntheticSensorConfig{});
  StreamDecoder late_decoder(Calibration::nominal(), {}, frames);
  std::vector<std::vector<std::uint8_t>> plain_sent;
  for (int k = 0; k < 200; ++k) {
    const std::size_t size = plain.next(buffer);
    plain_sent.emplace_back(buffer.begin(), buffer.begin() + static_cast<long>(size));
    late_decoder.process(plain_sent.back());
  }
  late_decoder.process(plain_sent[200 - kDuplicateWindow - 1]);
  late_decoder.process(plain_sent[199]);  // inside the window: a duplicate
  late_decoder.flush();
  CHECK(late_decoder.stats().duplicates == 1);
  CHECK(late_decoder.stats().accepted == 201);
  CHECK(late_decoder.stats().outliers == 0);
  CHECK(late_decoder.frames().azimuth_backward_steps >= 1);
}

TEST_CASE("a glitch every few hundred packets leaves at least 95 % of revolutions whole",
          "[stream][glitch]") {
  for (const ReturnMode mode : {ReturnMode::kDual, ReturnMode::kLast}) {
    SyntheticSensorConfig config;
    config.return_mode = mode;
    const int packets = mode == ReturnMode::kDual ? 14400 : 7200;  // 4 s, 40 revolutions
    const GlitchOutcome clean = run_glitches(packets, kClean, config);
    for (const int every : {200, 500}) {
      INFO("one packet in " << every << ", " << to_string(mode));
      std::mt19937 rng(static_cast<unsigned>(every));
      std::uint64_t glitches = 0;
      const GlitchOutcome glitched = run_glitches(
          packets,
          [&](int k, PacketContents& c) {
            if (k % every != every / 2) return true;
            ++glitches;
            switch (rng() % 4) {
              case 0:
                shift_time(
                    c, -static_cast<std::int64_t>(1 + rng() % 5000) * kNsPerMillisecond);  // back
                break;
              case 1:
                shift_time(
                    c, static_cast<std::int64_t>(60 + rng() % 5000) * kNsPerMillisecond);  // leap
                break;
              case 2:
                shift_azimuth(c, static_cast<int>(9100 + rng() % 17800));  // out of order
                break;
              default:
                shift_azimuth(c, 100 + static_cast<int>(rng() % 3000));  // ahead, 1° to 31°
                break;
            }
            return true;
          },
          config);
      CHECK(glitched.stats.outliers == glitches);
      CHECK(glitched.frames.discontinuities == 0);
      CHECK(static_cast<double>(glitched.frames.frames_complete) >=
            0.95 * static_cast<double>(clean.frames.frames_complete));
    }
  }
}
