// The stream decoder end to end: SyntheticSensor -> StreamDecoder -> FrameCollector, checked by
// the cut's observable property: per channel, corrected azimuths only ever wrap at a frame
// boundary; N seconds give about N x the frame rate; losses at the cut or of a whole revolution
// never mix two revolutions in a frame.
#include <algorithm>
#include <array>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdint>
#include <functional>
#include <utility>
#include <vector>

#include "core/decode/calibration.hpp"
#include "core/decode/decoder.hpp"
#include "core/decode/stream_decoder.hpp"
#include "core/frames/frame.hpp"
#include "core/frames/frame_collector.hpp"
#include "core/sensors/timing.hpp"
#include "core/sim/synthetic_sensor.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
using test::floor_div;
using test::floor_mod;
using test::kCircle;

namespace {

struct ChannelDigest {
  std::size_t count = 0;
  std::int64_t first_t = 0, last_t = 0;
  std::int64_t first_rel = 0, last_rel = 0;  // corrected azimuth - cut, 0..35999
  std::size_t wraps = 0;                     // decreases of that azimuth in time order
};

struct FrameDigest {
  FrameInfo info;
  std::size_t used = 0;
  std::int64_t min_t = 0, max_t = 0;
  std::array<ChannelDigest, kChannels> channels;
};

FrameDigest digest(const Frame& frame, int cut_cdeg) {
  FrameDigest d;
  d.info = frame.info;
  d.used = frame.used().size();
  std::array<std::vector<std::pair<std::int64_t, std::int64_t>>, kChannels> by_channel;
  bool first = true;
  for (const Point& p : frame.used()) {
    d.min_t = first ? p.timestamp_ns : std::min(d.min_t, p.timestamp_ns);
    d.max_t = first ? p.timestamp_ns : std::max(d.max_t, p.timestamp_ns);
    first = false;
    by_channel[p.channel].push_back(
        {p.timestamp_ns, floor_mod(p.azimuth_cdeg - cut_cdeg, kCircle)});
  }
  for (int c = 0; c < kChannels; ++c) {
    auto& v = by_channel[c];
    ChannelDigest& cd = d.channels[c];
    cd.count = v.size();
    if (v.empty()) continue;
    std::stable_sort(v.begin(), v.end(),
                     [](const auto& a, const auto& b) { return a.first < b.first; });
    for (std::size_t i = 1; i < v.size(); ++i)
      if (v[i].second < v[i - 1].second) ++cd.wraps;
    cd.first_t = v.front().first;
    cd.first_rel = v.front().second;
    cd.last_t = v.back().first;
    cd.last_rel = v.back().second;
  }
  return d;
}

struct EndToEnd {
  std::vector<FrameDigest> frames;
  StreamStats stream;
  AssemblerStats assembler;
  std::int64_t first_block_u = 0;  // unwrapped block azimuth - cut, first and last block fed
  std::int64_t last_block_u = 0;
  std::pair<int, int> bounds;
};

// Runs `packets` synthetic packets (skipping those `lose` says) through the decode path.
EndToEnd run_end_to_end(const SyntheticSensorConfig& sensor_config, int packets, int cut_cdeg,
                        const std::function<bool(int, std::uint16_t)>& lose = {}) {
  EndToEnd result;
  SyntheticSensor sensor(sensor_config);
  FrameCollector collector(3, kDefaultFrameCapacityPoints, [&](const Frame& frame) {
    result.frames.push_back(digest(frame, cut_cdeg));
  });
  StreamDecoderConfig config;
  config.cut_angle_deg = cut_cdeg / 100.0;
  StreamDecoder decoder(Calibration::nominal(), config, collector);
  result.bounds = decoder.decoder().relative_azimuth_bounds_cdeg();
  std::array<std::uint8_t, kMaxPacketBytes> buffer{};
  bool started = false;
  std::uint16_t previous = 0;
  for (int k = 0; k < packets; ++k) {
    const std::size_t size = sensor.next(buffer);
    const auto view = PacketView::make(std::span(buffer).first(size));
    REQUIRE(view.has_value());
    // Unwrap the block azimuth (it only ever steps forward by a fraction of a degree).
    for (int b = 0; b < kBlocks; ++b) {
      const std::uint16_t az = view->azimuth_cdeg(b);
      if (!started) {
        result.first_block_u = floor_mod(az - cut_cdeg, kCircle);
        result.last_block_u = result.first_block_u;
        started = true;
      } else {
        result.last_block_u += floor_mod(az - previous, kCircle);
      }
      previous = az;
    }
    if (lose && lose(k, view->azimuth_cdeg(0))) continue;
    REQUIRE(decoder.process(std::span(buffer).first(size)) == RejectReason::kNone);
  }
  decoder.flush();
  result.stream = decoder.stats();
  result.assembler = decoder.frames();
  return result;
}

// Whole frames the contract promises for a stream covering [first_block_u, last_block_u].
std::int64_t expected_complete(const EndToEnd& e) {
  std::int64_t n = 0;
  for (std::int64_t f = floor_div(e.first_block_u, kCircle) - 1;
       f <= floor_div(e.last_block_u, kCircle) + 1; ++f) {
    if (f * kCircle >= e.first_block_u + e.bounds.second &&
        (f + 1) * kCircle <= e.last_block_u + e.bounds.first)
      ++n;
  }
  return n;
}

// The per-channel cut seen in decoded frames: within a frame a channel's azimuth never wraps;
// from one frame to the next it wraps exactly once, and time moves on. Returns the number of
// frame boundaries skipped because the stream broke there (more than half a revolution of
// time between the frames: the two sides are not neighbouring revolutions).
// `edge_step_cdeg` > 0: no packets were lost near the cut, so a whole frame's channel 0 must
// start and end within one azimuth step (+1 for rounding) of the cut.
std::size_t check_cut_property(const EndToEnd& e, std::int64_t revolution_ns, int edge_step_cdeg) {
  std::size_t breaks = 0;
  for (std::size_t i = 0; i < e.frames.size(); ++i) {
    const FrameDigest& f = e.frames[i];
    INFO("frame " << i << " sequence " << f.info.sequence);
    const bool broken = i > 0 && f.info.start_ns - e.frames[i - 1].info.end_ns > revolution_ns / 2;
    if (broken) ++breaks;
    for (int c = 0; c < kChannels; ++c) {
      INFO("channel " << c);
      CHECK(f.channels[c].wraps == 0);
      if (!f.info.partial) CHECK(f.channels[c].count > 0);  // every channel in a whole frame
      if (i == 0 || broken || f.channels[c].count == 0 || e.frames[i - 1].channels[c].count == 0)
        continue;
      const ChannelDigest& before = e.frames[i - 1].channels[c];
      const ChannelDigest& now = f.channels[c];
      CHECK(before.last_t < now.first_t);
      CHECK(now.first_rel < before.last_rel);
    }
    // Channel 0 (elevation +15°) sees a wall or the ceiling in every direction: in a whole frame
    // it runs from within one azimuth step after the cut to within one step before it.
    if (!f.info.partial && edge_step_cdeg > 0) {
      CHECK(f.channels[0].first_rel <= edge_step_cdeg + 1);
      CHECK(f.channels[0].last_rel >= kCircle - edge_step_cdeg - 1);
    }
  }
  return breaks;
}

}  // namespace

TEST_CASE("end to end: N seconds give about N x frame rate frames, partial at both ends",
          "[assembler]") {
  struct Case {
    int rpm;
    ReturnMode mode;
    int cut;
    double seconds;
  };
  for (const Case& tc :
       {Case{600, ReturnMode::kDual, 0, 2.0}, Case{1200, ReturnMode::kStrongest, 0, 2.0},
        Case{600, ReturnMode::kDual, 9000, 1.0}, Case{1200, ReturnMode::kLast, 35999, 1.0}}) {
    INFO("rpm " << tc.rpm << " " << to_string(tc.mode) << " cut " << tc.cut);
    SyntheticSensorConfig config;
    config.rpm = tc.rpm;
    config.return_mode = tc.mode;
    config.start_azimuth_deg = 180.0;
    const int packets_per_second = tc.mode == ReturnMode::kDual ? 3600 : 1800;
    const int packets = static_cast<int>(tc.seconds * packets_per_second);
    const EndToEnd e = run_end_to_end(config, packets, tc.cut);

    const int revolutions = static_cast<int>(std::lround(tc.seconds * tc.rpm / 60.0));
    const auto complete = static_cast<std::int64_t>(e.assembler.frames_complete);
    CHECK(complete == expected_complete(e));
    CHECK(complete >= revolutions - 1);
    CHECK(complete <= revolutions);
    CHECK(e.assembler.frames_partial == 2);
    CHECK(e.frames.size() == e.assembler.frames_complete + e.assembler.frames_partial);
    CHECK(e.assembler.frames_dropped == 0);
    CHECK(e.assembler.discontinuities == 0);
    CHECK(e.assembler.azimuth_backward_steps == 0);
    CHECK(e.assembler.points_late == 0);
    CHECK(e.assembler.points_dropped_full == 0);
    CHECK(e.assembler.points_dropped_no_frame == 0);

    REQUIRE(e.frames.size() >= 3);
    CHECK(e.frames.front().info.partial);
    CHECK(e.frames.back().info.partial);
    std::uint64_t points = 0;
    const std::int64_t revolution_ns = 60'000'000'000LL / tc.rpm;
    const double degrees_per_packet =
        tc.rpm / 60.0 * 360.0 * static_cast<double>(packet_period_ns(tc.mode)) * 1e-9;
    for (std::size_t i = 0; i < e.frames.size(); ++i) {
      const FrameDigest& f = e.frames[i];
      INFO("frame " << i);
      CHECK(f.info.sequence == i);
      if (i > 0 && i + 1 < e.frames.size()) CHECK_FALSE(f.info.partial);
      CHECK(f.info.points == f.used);
      CHECK(f.info.points_dropped == 0);
      CHECK(f.info.start_ns == f.min_t);
      CHECK(f.info.end_ns == f.max_t);
      CHECK(f.info.start_ns <= f.info.end_ns);
      CHECK(f.info.return_mode == tc.mode);
      CHECK(f.info.time_valid);
      CHECK(f.info.rpm >= tc.rpm - 2);
      CHECK(f.info.rpm <= tc.rpm + 2);
      points += f.info.points;
      // Coverage: a whole revolution (clamped at 360°) for a complete frame; for the first,
      // from where the stream started to the cut (± the channels' azimuth offsets).
      if (!f.info.partial) CHECK(f.info.azimuth_span_cdeg >= 35900);
      CHECK(f.info.azimuth_span_cdeg <= 36000);
      if (i == 0) {
        const int start_after_cut = (18000 - tc.cut + 36000) % 36000;
        CHECK(std::abs(static_cast<int>(f.info.azimuth_span_cdeg) - (36000 - start_after_cut)) <=
              1000);
      }
      if (!f.info.partial) {
        // One revolution of time, plus at most the ~8.3° seam and a firing round.
        const std::int64_t span = f.info.end_ns - f.info.start_ns;
        CHECK(span >= revolution_ns - 2 * kRoundPeriodNs);
        CHECK(span <= revolution_ns * (36000 + 840) / 36000 + 2 * kRoundPeriodNs);
        // 360° plus the seam, in packets.
        const double seam_packets = (360.0 + 8.4) / degrees_per_packet;
        CHECK(f.info.packets >= std::floor(360.0 / degrees_per_packet));
        CHECK(f.info.packets <= std::ceil(seam_packets) + 1);
      }
    }
    CHECK(points == e.stream.points);
    CHECK(check_cut_property(e, revolution_ns, tc.rpm / 30) == 0);
  }
}

TEST_CASE(
    "end to end: losing packets at the cut changes no frame count, mixes nothing, and makes "
    "the frames that lost them partial",
    "[assembler]") {
  for (const int rpm : {600, 1200}) {
    SyntheticSensorConfig config;
    config.rpm = rpm;
    config.return_mode = rpm == 600 ? ReturnMode::kDual : ReturnMode::kStrongest;
    config.start_azimuth_deg = 180.0;
    const int packets = rpm == 600 ? 3600 : 1800;  // one second
    const EndToEnd reference = run_end_to_end(config, packets, 0);
    for (const int k_lost : {1, 3, 10}) {
      INFO("rpm " << rpm << " lost " << k_lost << " packets at each cut");
      // Lose the k_lost packets that start within k_lost/2 packets' azimuth before the cut.
      const int per_packet_cdeg = rpm / 30 * rounds_per_packet(config.return_mode);
      std::vector<int> lost;
      const EndToEnd e = run_end_to_end(config, packets, 0, [&](int k, std::uint16_t az0) {
        const std::int64_t before_cut = floor_mod(-static_cast<std::int64_t>(az0), kCircle);
        const bool lose =
            before_cut < static_cast<std::int64_t>(per_packet_cdeg) * ((k_lost + 1) / 2) ||
            kCircle - before_cut < static_cast<std::int64_t>(per_packet_cdeg) * (k_lost / 2);
        if (lose) lost.push_back(k);
        return lose;
      });
      CHECK(lost.size() >= static_cast<std::size_t>(k_lost) * 9);  // at ~10 cuts
      CHECK(e.frames.size() == reference.frames.size());
      // Every revolution lost packets at both of its ends: none is whole, and what was lost is
      // counted in packets.
      CHECK(e.assembler.frames_complete == 0);
      CHECK(e.assembler.frames_holed == reference.assembler.frames_complete);
      CHECK(e.assembler.packets_missing == lost.size());
      CHECK(e.assembler.discontinuities == 0);
      CHECK(e.assembler.points_late == 0);
      std::uint64_t points = 0;
      for (const FrameDigest& f : e.frames)
        points += f.info.points;
      CHECK(points == e.stream.points);
      CHECK(points < reference.stream.points);
      CHECK(check_cut_property(e, 60'000'000'000LL / rpm, 0) == 0);
    }
  }
}

TEST_CASE("end to end: a lost revolution restarts cutting instead of merging two revolutions",
          "[assembler]") {
  SyntheticSensorConfig config;
  config.rpm = 600;
  config.return_mode = ReturnMode::kDual;
  config.start_azimuth_deg = 180.0;
  // Packets 1000..1359 (exactly one revolution) never arrive: the azimuth looks continuous.
  const EndToEnd e =
      run_end_to_end(config, 3600, 0, [](int k, std::uint16_t) { return k >= 1000 && k < 1360; });
  CHECK(e.assembler.discontinuities == 1);
  CHECK(check_cut_property(e, 100'000'000, 20) == 1);
  // Every frame is at most one revolution long.
  for (const FrameDigest& f : e.frames)
    CHECK(f.info.end_ns - f.info.start_ns <=
          100'000'000LL * (36000 + 840) / 36000 + 2 * kRoundPeriodNs);
  // Two streams, each with a partial frame at either end.
  CHECK(e.assembler.frames_partial == 4);
}
