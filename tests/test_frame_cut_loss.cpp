// Frame cutting with packets lost at the cut: the simulated sensor's stream, with the packets
// around every crossing of the cut angle removed, must give the same frames as the full stream,
// and no frame may mix two revolutions.
#include <catch2/catch.hpp>
#include <map>
#include <vector>

#include "core/frame_collector.hpp"
#include "core/sim/synthetic_sensor.hpp"
#include "core/stream_decoder.hpp"

using namespace pandarcap;

namespace {

struct Result {
  std::uint64_t complete = 0, partial = 0;
  bool sorted = true;  // per channel, azimuths rise through every complete frame (no wrap)
};

// Runs 2 s of the simulated sensor; drops `lose` packets starting at each cut crossing.
Result run(ReturnMode mode, int rpm, double cut_deg, int lose) {
  SyntheticSensorConfig config;
  config.rpm = rpm;
  config.return_mode = mode;
  config.start_azimuth_deg = 123.0;
  SyntheticSensor sensor(config);
  Result result;
  FrameCollector collector(3, kDefaultFrameCapacityPoints, [&](const Frame& frame) {
    if (frame.info.partial) {
      ++result.partial;
      return;
    }
    ++result.complete;
    const int cut = static_cast<int>(cut_deg * 100);
    std::map<int, int> last;  // channel -> azimuth relative to the cut
    for (const Point& p : frame.used()) {
      const int rel = (p.azimuth_cdeg - cut + 36000) % 36000;
      if (last.count(p.channel) && rel < last[p.channel]) result.sorted = false;
      last[p.channel] = rel;
    }
  });
  StreamDecoderConfig decode;
  decode.cut_angle_deg = cut_deg;
  StreamDecoder decoder(Calibration::nominal(), decode, collector);
  std::array<std::uint8_t, kMaxPacketBytes> buffer{};
  const int packets = mode == ReturnMode::kDual ? 7200 : 3600;
  int to_drop = 0;
  int previous = -1;
  const int cut = static_cast<int>(cut_deg * 100);
  for (int k = 0; k < packets; ++k) {
    const std::size_t size = sensor.next(buffer);
    const auto view = PacketView::make(std::span(buffer).first(size));
    REQUIRE(view.has_value());
    const int first = (view->azimuth_cdeg(0) - cut + 36000) % 36000;
    if (previous >= 0 && first < previous) to_drop = lose;  // this packet crossed the cut
    previous = first;
    if (to_drop > 0) {
      --to_drop;
      continue;
    }
    decoder.process(std::span(buffer).first(size));
  }
  decoder.flush();
  CHECK(decoder.frames().discontinuities == 0);
  return result;
}

}  // namespace

TEST_CASE("losing packets at the cut changes no frame count and mixes nothing", "[assembler]") {
  for (ReturnMode mode : {ReturnMode::kDual, ReturnMode::kStrongest}) {
    for (int rpm : {600, 1200}) {
      for (double cut : {0.0, 90.0, 359.99}) {
        const Result full = run(mode, rpm, cut, 0);
        INFO("mode " << to_string(mode) << " rpm " << rpm << " cut " << cut);
        CHECK(full.sorted);
        CHECK(full.complete >= static_cast<std::uint64_t>(2 * rpm / 60 - 2));
        for (int lose : {1, 2, 5}) {
          INFO("lose " << lose << " packets at each cut");
          const Result lossy = run(mode, rpm, cut, lose);
          CHECK(lossy.complete == full.complete);
          CHECK(lossy.partial == full.partial);
          CHECK(lossy.sorted);
        }
      }
    }
  }
}
