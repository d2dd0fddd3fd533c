// The real dual-return capture (tier4/nebula test data, 600 RPM, 1262-byte packets) decoded end
// to end with its own calibration file. The checks are physical: they fail if the geometry,
// timing, dual-return labelling or frame cutting is wrong, without hard-coding decoder output.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <map>
#include <vector>

#include "core/decode/decoder.hpp"
#include "core/decode/packet_time.hpp"
#include "core/decode/stream_decoder.hpp"
#include "core/frames/frame_collector.hpp"
#include "daemon/io/calibration_file.hpp"
#include "daemon/pcap/capture_reader.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;

namespace {

constexpr const char* kDualCapture = "pandar40p_nebula_dual_600rpm_1262B.pcap";
constexpr const char* kCalibration = "nebula_Pandar40P_calibration.csv";

std::vector<std::vector<std::uint8_t>> read_payloads(const std::string& path) {
  CaptureReader reader(path);
  std::vector<std::vector<std::uint8_t>> payloads;
  CaptureRecord record;
  CaptureStatus status;
  while ((status = reader.next(record)) == CaptureStatus::kRecord) {
    payloads.emplace_back(record.payload.begin(), record.payload.end());
  }
  REQUIRE(status == CaptureStatus::kEnd);
  return payloads;
}

// Mean |range difference| (capped at 5 m) of two channels at the same corrected azimuth, in
// 0.2° bins over one revolution. Adjacent channels are 1/3° apart in elevation, so with the
// right azimuth offsets they see nearly the same range profile.
double misalignment(const std::vector<std::vector<std::uint8_t>>& payloads,
                    const Calibration& calibration, int a, int b) {
  ScalarDecoder decoder(calibration, {});
  std::array<Point, kMaxPointsPerPacket> points{};
  FilterCounts filtered;
  std::vector<double> range_a(1800, -1), range_b(1800, -1);
  for (std::size_t k = 0; k < std::min<std::size_t>(360, payloads.size()); ++k) {
    const DecodedPacket d =
        decoder.decode(PacketView::assume_valid(payloads[k]), 0, points, filtered);
    for (std::size_t i = 0; i < d.point_count; ++i) {
      const Point& p = points[i];
      if (p.return_type == ReturnType::kLast) continue;
      if (p.channel == a) range_a[p.azimuth_cdeg / 20] = p.distance_m;
      if (p.channel == b) range_b[p.azimuth_cdeg / 20] = p.distance_m;
    }
  }
  double sum = 0;
  int n = 0;
  for (std::size_t i = 0; i < range_a.size(); ++i) {
    if (range_a[i] > 0 && range_b[i] > 0) {
      sum += std::min(std::fabs(range_a[i] - range_b[i]), 5.0);
      ++n;
    }
  }
  REQUIRE(n > 500);
  return sum / n;
}

}  // namespace

TEST_CASE("real dual capture: packets, RPM, return mode and frames", "[real][e2e]") {
  const auto capture = test::real_capture(kDualCapture);
  const auto calibration_path = test::real_capture(kCalibration);
  if (!capture || !calibration_path) return;
  const Calibration calibration = load_calibration(calibration_path->string());

  std::vector<FrameInfo> frames;
  std::map<std::uint64_t, std::map<int, std::vector<std::uint16_t>>> azimuths;  // frame->ch->az
  std::uint64_t points_in_frames = 0;
  FrameCollector collector(3, kDefaultFrameCapacityPoints, [&](const Frame& frame) {
    frames.push_back(frame.info);
    points_in_frames += frame.size;
    CHECK(frame.size == frame.info.points);
    if (frame.info.partial) return;
    for (const Point& p : frame.used())
      azimuths[frame.info.sequence][p.channel].push_back(p.azimuth_cdeg);
    // Frame time span: one revolution (100 ms at 600 RPM) plus the spread of channel offsets.
    const double span_ms = static_cast<double>(frame.info.end_ns - frame.info.start_ns) / 1e6;
    CHECK(span_ms > 98.0);
    CHECK(span_ms < 104.0);
  });
  StreamDecoder decoder(calibration, {}, collector);
  for (const auto& payload : read_payloads(capture->string()))
    decoder.process(payload);
  decoder.flush();

  const StreamStats& s = decoder.stats();
  CHECK(s.packets == 1439);
  CHECK(s.accepted == 1439);
  CHECK(s.rejected() == 0);
  CHECK(s.rpm_min >= 598);
  CHECK(s.rpm_max <= 602);
  REQUIRE(s.return_mode.has_value());
  CHECK(*s.return_mode == ReturnMode::kDual);
  CHECK(s.bad_date == 0);
  CHECK(s.static_timestamps == 0);
  CHECK(s.sequence_packets == 0);
  // Every channel slot is a point or a counted filter: 1439 packets x 400 slots.
  CHECK(s.points + s.filtered.total() == 1439ull * 400);
  // Every point ended up in a frame (none late, none dropped).
  const AssemblerStats& fs = decoder.frames();
  CHECK(fs.points_late == 0);
  CHECK(fs.frames_dropped == 0);
  CHECK(fs.discontinuities == 0);
  CHECK(points_in_frames == s.points);

  // ~4 revolutions starting just after the cut: the first and last frames are partial, the
  // revolutions in between complete, each ~360 packets (3600 packets/s at 10 Hz).
  std::size_t complete = 0;
  for (const FrameInfo& f : frames) {
    if (f.partial) continue;
    ++complete;
    CHECK(f.packets >= 355);
    CHECK(f.packets <= 370);
    CHECK(f.rpm == Approx(600).margin(2));
    CHECK(f.time_valid);
  }
  CHECK(complete == fs.frames_complete);
  CHECK(complete >= 2);
  CHECK(frames.front().partial);
  CHECK(frames.back().partial);
  for (std::size_t i = 1; i < frames.size(); ++i)
    CHECK(frames[i].sequence == frames[i - 1].sequence + 1);

  // Per-channel cut: in a complete frame every channel sweeps once from the cut (0°) round to
  // just before it, so its azimuths, in arrival order, never wrap. Channels that see something
  // all round (most of them; a few look at the sky) start and end within 0.5° of the cut.
  REQUIRE(azimuths.size() == complete);
  for (const auto& [sequence, channels] : azimuths) {
    int full_circle_channels = 0;
    for (const auto& [channel, az] : channels) {
      INFO("frame " << sequence << " channel " << channel);
      CHECK(std::is_sorted(az.begin(), az.end()));
      if (az.front() < 50 && az.back() > 35950) ++full_circle_channels;
    }
    CHECK(full_circle_channels >= 30);
  }
}

TEST_CASE("real dual capture: the calibration's offsets align adjacent channels",
          "[real][geometry]") {
  const auto capture = test::real_capture(kDualCapture);
  const auto calibration_path = test::real_capture(kCalibration);
  if (!capture || !calibration_path) return;
  const auto payloads = read_payloads(capture->string());
  const Calibration right = load_calibration(calibration_path->string());
  Calibration negated = right;  // offsets subtracted instead of added
  for (double& offset : negated.azimuth_offset_deg)
    offset = -offset;

  // Channels 7-30 carry the three different offsets (+3.125, -5.208, -1.042).
  for (int c = 6; c < 29; ++c) {
    INFO("channels " << c + 1 << " and " << c + 2);
    const double good = misalignment(payloads, right, c, c + 1);
    CHECK(good < 0.35);
    CHECK(misalignment(payloads, negated, c, c + 1) > 2 * good);
  }
}

TEST_CASE("real dual capture: timing and dual-return labelling", "[real][timing]") {
  const auto capture = test::real_capture(kDualCapture);
  const auto calibration_path = test::real_capture(kCalibration);
  if (!capture || !calibration_path) return;
  const auto payloads = read_payloads(capture->string());
  ScalarDecoder decoder(load_calibration(calibration_path->string()), {});
  PacketClock clock;
  std::array<Point, kMaxPointsPerPacket> points{};
  FilterCounts filtered;

  std::int64_t previous_t0 = 0, previous_latest = 0;
  std::size_t regular_steps = 0, both_echoes = 0, last_farther = 0;
  for (std::size_t k = 0; k < payloads.size(); ++k) {
    const PacketView view = PacketView::assume_valid(payloads[k]);
    const PacketTime t = clock.convert(view.utc(), view.timestamp_us());
    REQUIRE(t.valid());
    const DecodedPacket d = decoder.decode(view, t.t0_ns, points, filtered);
    std::int64_t earliest = INT64_MAX, latest = INT64_MIN;
    std::map<int, float> last_by_channel[kBlocks / 2];
    for (int b = 0; b < kBlocks; ++b) {
      for (std::size_t i = d.block_begin[b]; i < d.block_begin[b + 1]; ++i) {
        const Point& p = points[i];
        earliest = std::min(earliest, p.timestamp_ns);
        latest = std::max(latest, p.timestamp_ns);
        CHECK(p.timestamp_ns < t.t0_ns);
        if (p.return_type == ReturnType::kLast) last_by_channel[b / 2][p.channel] = p.distance_m;
        if (p.return_type == ReturnType::kStrongest) {
          const auto found = last_by_channel[b / 2].find(p.channel);
          if (found != last_by_channel[b / 2].end()) {
            ++both_echoes;
            if (found->second >= p.distance_m) ++last_farther;
          }
        }
      }
    }
    if (k > 0) {
      // Packets are 5 firing rounds = 277.8 µs apart, and a packet's points all fire after the
      // previous packet's: with the single-return table (or APO's dual indexing bug) they would
      // overlap by up to 277.8 µs.
      const std::int64_t step = t.t0_ns - previous_t0;
      if (step > 276'000 && step < 280'000) ++regular_steps;
      CHECK(earliest > previous_latest);
      CHECK(earliest - previous_latest < 20'000);
    }
    previous_t0 = t.t0_ns;
    previous_latest = latest;
  }
  CHECK(regular_steps == payloads.size() - 1);
  // Spec §1.5: where both echoes exist the even ("last") block is the farther one.
  CHECK(both_echoes > 1000);
  CHECK(last_farther == both_echoes);
  // ~96.6 % of channel pairs are byte-identical, so duplicates dominate the dual filter.
  CHECK(filtered[FilterReason::kDualDuplicate] > 10 * both_echoes);
}
