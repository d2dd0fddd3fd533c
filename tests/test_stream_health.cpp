// The health figures the stream decoder derives for the daemon: azimuth gaps (loss without a UDP
// sequence), the measured spin rate from azimuth progression over packet time, and the last
// packet's tail values.
#include <array>
#include <catch2/catch.hpp>
#include <cmath>
#include <vector>

#include "core/decode/calibration.hpp"
#include "core/decode/stream_decoder.hpp"
#include "core/frames/frame_collector.hpp"
#include "core/sim/synthetic_sensor.hpp"
#include "daemon/pcap/capture_reader.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;

namespace {

struct HealthRun {
  StreamStats stats;
  SequenceStats sequence;
};

// Feeds `packets` synthetic packets, skipping those whose index is in `lose`.
HealthRun run_synthetic(int rpm, ReturnMode mode, bool udp_sequence, int packets,
                        const std::vector<int>& lose) {
  SyntheticSensorConfig config;
  config.rpm = rpm;
  config.return_mode = mode;
  config.udp_sequence = udp_sequence;
  SyntheticSensor sensor(config);
  FrameCollector frames(3, kDefaultFrameCapacityPoints, [](const Frame&) {});
  StreamDecoder decoder(Calibration::nominal(), {}, frames);
  std::array<std::uint8_t, kMaxPacketBytes> buffer{};
  for (int k = 0; k < packets; ++k) {
    const std::size_t size = sensor.next(buffer);
    if (std::find(lose.begin(), lose.end(), k) != lose.end()) continue;
    decoder.process(std::span(buffer).first(size));
  }
  return {decoder.stats(), decoder.sequence()};
}

double measured_rpm(const StreamStats& s) {
  return (static_cast<double>(s.measured_azimuth_cdeg) / 36000.0) /
         (static_cast<double>(s.measured_time_ns) / 60e9);
}

}  // namespace

TEST_CASE("measured RPM follows the azimuth over packet time", "[stream][health]") {
  for (int rpm : {600, 1200}) {
    for (ReturnMode mode : {ReturnMode::kDual, ReturnMode::kLast}) {
      INFO(rpm << " RPM, mode " << to_string(mode));
      const HealthRun run = run_synthetic(rpm, mode, false, 2000, {});
      CHECK(run.stats.azimuth_gaps == 0);
      CHECK(measured_rpm(run.stats) == Approx(rpm).epsilon(0.01));
      CHECK(std::abs(run.stats.last_rpm - rpm) <= 2);
      CHECK_FALSE(run.stats.last_high_temperature);
    }
  }
}

TEST_CASE("without a sequence, lost packets show as azimuth gaps", "[stream][health]") {
  // Three separate losses: one packet, two packets, ten packets.
  std::vector<int> lose = {100, 500, 501};
  for (int k = 900; k < 910; ++k)
    lose.push_back(k);
  const HealthRun dual = run_synthetic(600, ReturnMode::kDual, false, 1500, lose);
  CHECK(dual.stats.azimuth_gaps == 3);
  // The gaps do not distort the measured speed.
  CHECK(measured_rpm(dual.stats) == Approx(600).epsilon(0.01));
  const HealthRun single = run_synthetic(1200, ReturnMode::kStrongest, false, 1500, lose);
  CHECK(single.stats.azimuth_gaps == 3);
}

TEST_CASE("with a sequence, loss is the sequence tracker's, not an azimuth gap",
          "[stream][health]") {
  const HealthRun run = run_synthetic(600, ReturnMode::kDual, true, 1000, {10, 11, 12});
  CHECK(run.stats.azimuth_gaps == 0);
  CHECK(run.sequence.gaps == 1);
  CHECK(run.sequence.lost == 3);
}

TEST_CASE("real capture: no azimuth gaps and a measured speed near 600 RPM", "[stream][health]") {
  const auto capture = test::real_capture("pandar40p_nebula_dual_600rpm_1262B.pcap");
  if (!capture) return;
  CaptureReader reader(capture->string());
  FrameCollector frames(3, kDefaultFrameCapacityPoints, [](const Frame&) {});
  StreamDecoder decoder(Calibration::nominal(), {}, frames);
  CaptureRecord record;
  while (reader.next(record) == CaptureStatus::kRecord)
    decoder.process(record.payload);
  CHECK(decoder.stats().azimuth_gaps == 0);
  CHECK(measured_rpm(decoder.stats()) == Approx(600).margin(6));
}

namespace {

// Two seconds of the simulated sensor (600 RPM, dual) with each packet's tail time changed by
// `alter(index, tail)`; the stream's counters and frames.
struct ClockRun {
  StreamStats stats;
  AssemblerStats frames;
};
template <typename Alter>
ClockRun run_with_clock(Alter&& alter) {
  SyntheticSensor sensor(SyntheticSensorConfig{});
  FrameCollector frames(3, kDefaultFrameCapacityPoints, [](const Frame&) {});
  StreamDecoder decoder(Calibration::nominal(), {}, frames);
  std::array<std::uint8_t, kMaxPacketBytes> buffer{};
  Tail previous;
  for (int k = 0; k < 7200; ++k) {
    PacketContents contents = sensor.next_contents();
    const Tail original = contents.tail;
    alter(k, contents.tail, previous);
    previous = original;
    const std::size_t size = encode(contents, buffer);
    REQUIRE(decoder.process(std::span(buffer).first(size)) == RejectReason::kNone);
  }
  decoder.flush();
  return {decoder.stats(), decoder.frames()};
}

}  // namespace

TEST_CASE(
    "packet clock frozen, stepping back and leaping: each counted - only the leap cuts a "
    "frame",
    "[stream][health][time]") {
  const ClockRun clean = run_with_clock([](int, Tail&, const Tail&) {});
  CHECK(clean.stats.static_timestamps == 0);
  CHECK(clean.stats.backward_timestamps == 0);
  CHECK(clean.stats.timestamp_jumps == 0);
  CHECK(clean.frames.discontinuities == 0);
  REQUIRE(clean.frames.frames_complete >= 18);

  Tail frozen;
  const auto freeze_and_step_back = [&](int k, Tail& tail, const Tail& previous) {
    // Frozen: packets 1000..1009 carry packet 999's time.
    if (k == 999) frozen = tail;
    if (k >= 1000 && k <= 1009) {
      tail.utc = frozen.utc;
      tail.timestamp_us = frozen.timestamp_us;
    }
    // Back: packet 3000 is 5 ms older than packet 2999 (a clock stepped back by a resync).
    if (k == 3000) {
      tail.utc = previous.utc;
      tail.timestamp_us = previous.timestamp_us >= 5000 ? previous.timestamp_us - 5000 : 0;
    }
  };
  const ClockRun moody = run_with_clock(freeze_and_step_back);
  CHECK(moody.stats.static_timestamps == 10);
  CHECK(moody.stats.backward_timestamps == 1);
  CHECK(moody.stats.timestamp_jumps == 0);
  CHECK(moody.stats.bad_date == 0);
  CHECK(moody.stats.azimuth_gaps == 0);
  // Frames are cut by azimuth: a frozen or stepped-back clock changes no frame and loses no point.
  CHECK(moody.frames.frames_complete == clean.frames.frames_complete);
  CHECK(moody.frames.frames_partial == clean.frames.frames_partial);
  CHECK(moody.frames.discontinuities == 0);
  CHECK(moody.stats.points == clean.stats.points);

  // Leap: from packet 5000 on, a minute later (a sensor that found its GPS time). More than half
  // a revolution of packet time between two packets is a discontinuity to the assembler (as
  // after a loss or a restart): the frame in progress ends partial, the next starts afresh.
  const ClockRun leap = run_with_clock([&](int k, Tail& tail, const Tail& previous) {
    freeze_and_step_back(k, tail, previous);
    if (k >= 5000) tail.utc.minute = static_cast<std::uint8_t>((tail.utc.minute + 1) % 60);
  });
  CHECK(leap.stats.timestamp_jumps == 1);
  CHECK(leap.stats.backward_timestamps == 1);
  CHECK(leap.frames.discontinuities == 1);
  CHECK(leap.frames.frames_complete + 1 == clean.frames.frames_complete);
  CHECK(leap.stats.points == clean.stats.points);
}
