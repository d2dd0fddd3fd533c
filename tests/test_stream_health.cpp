// The health figures the stream decoder derives for the daemon: azimuth gaps (loss without a UDP
// sequence), the measured spin rate from azimuth progression over packet time, and the last
// packet's tail values.
#include <array>
#include <catch2/catch.hpp>
#include <cmath>
#include <vector>

#include "core/calibration.hpp"
#include "core/capture_reader.hpp"
#include "core/frame_collector.hpp"
#include "core/stream_decoder.hpp"
#include "core/synthetic_sensor.hpp"
#include "test_support.hpp"

using namespace pandarcap;

namespace {

struct Run {
  StreamStats stats;
  SequenceStats sequence;
};

// Feeds `packets` synthetic packets, skipping those whose index is in `lose`.
Run run_synthetic(int rpm, ReturnMode mode, bool udp_sequence, int packets,
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
      const Run run = run_synthetic(rpm, mode, false, 2000, {});
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
  const Run dual = run_synthetic(600, ReturnMode::kDual, false, 1500, lose);
  CHECK(dual.stats.azimuth_gaps == 3);
  // The gaps do not distort the measured speed.
  CHECK(measured_rpm(dual.stats) == Approx(600).epsilon(0.01));
  const Run single = run_synthetic(1200, ReturnMode::kStrongest, false, 1500, lose);
  CHECK(single.stats.azimuth_gaps == 3);
}

TEST_CASE("with a sequence, loss is the sequence tracker's, not an azimuth gap",
          "[stream][health]") {
  const Run run = run_synthetic(600, ReturnMode::kDual, true, 1000, {10, 11, 12});
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
