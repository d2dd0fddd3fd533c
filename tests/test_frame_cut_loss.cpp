// Frame cutting with packets lost at the cut: the simulated sensor's stream, with the packets
// around every crossing of the cut angle removed, must give as many frames as the full stream,
// every one that lost a packet partial, and no frame may mix two revolutions.
#include <array>
#include <catch2/catch.hpp>
#include <vector>

#include "core/decode/stream_decoder.hpp"
#include "core/frames/frame_collector.hpp"
#include "core/sim/synthetic_sensor.hpp"

using namespace pandarcap;

namespace {

struct Result {
  std::uint64_t complete = 0, partial = 0;
  std::uint64_t packets_lost = 0, packets_missing = 0;  // dropped by the test, counted by it
  bool sorted = true;  // per channel, azimuths rise through every complete frame (no wrap)
};

// One packet of the simulated stream, with its first block's azimuth (read, and the packet checked,
// once, when the stream is made).
struct Packet {
  std::vector<std::uint8_t> bytes;
  int first_azimuth_cdeg = 0;
};

// 2 s of the simulated sensor. Made once per mode and speed and decoded for every cut and loss:
// generating it is a third of the work, and the test runs under the sanitizers.
std::vector<Packet> simulate(ReturnMode mode, int rpm) {
  SyntheticSensorConfig config;
  config.rpm = rpm;
  config.return_mode = mode;
  config.start_azimuth_deg = 123.0;
  SyntheticSensor sensor(config);
  std::array<std::uint8_t, kMaxPacketBytes> buffer{};
  std::vector<Packet> stream;
  const int packets = mode == ReturnMode::kDual ? 7200 : 3600;
  for (int k = 0; k < packets; ++k) {
    const auto body = std::span(buffer).first(sensor.next(buffer));
    const auto view = PacketView::make(body);
    REQUIRE(view.has_value());
    stream.push_back({{body.begin(), body.end()}, view->azimuth_cdeg(0)});
  }
  return stream;
}

// Decodes the stream, dropping `lose` packets starting at each cut crossing.
Result run(const std::vector<Packet>& stream, double cut_deg, int lose) {
  Result result;
  const int cut = static_cast<int>(cut_deg * 100);
  FrameCollector collector(3, kDefaultFrameCapacityPoints, [&](const Frame& frame) {
    if (frame.info.partial) {
      ++result.partial;
      return;
    }
    ++result.complete;
    // Per channel, the last azimuth relative to the cut (-1: none yet). A flat array, not a map:
    // this runs for every point of 48 decodes, under the sanitizers at -O0 too.
    std::array<int, kChannels> last;
    last.fill(-1);
    for (const Point& p : frame.used()) {
      const int rel = (p.azimuth_cdeg - cut + 36000) % 36000;
      if (rel < last.at(p.channel)) result.sorted = false;
      last.at(p.channel) = rel;
    }
  });
  StreamDecoderConfig decode;
  decode.cut_angle_deg = cut_deg;
  StreamDecoder decoder(Calibration::nominal(), decode, collector);
  int to_drop = 0;
  int previous = -1;
  for (const Packet& packet : stream) {
    const int first = (packet.first_azimuth_cdeg - cut + 36000) % 36000;
    if (previous >= 0 && first < previous) to_drop = lose;  // this packet crossed the cut
    previous = first;
    if (to_drop > 0) {
      --to_drop;
      ++result.packets_lost;
      continue;
    }
    decoder.process(packet.bytes);
  }
  decoder.flush();
  CHECK(decoder.frames().discontinuities == 0);
  result.packets_missing = decoder.frames().packets_missing;
  return result;
}

}  // namespace

TEST_CASE("losing packets at the cut: as many frames, none mixed, the ones that lost them partial",
          "[assembler]") {
  for (ReturnMode mode : {ReturnMode::kDual, ReturnMode::kStrongest}) {
    for (int rpm : {600, 1200}) {
      const std::vector<Packet> stream = simulate(mode, rpm);
      for (double cut : {0.0, 90.0, 359.99}) {
        const Result full = run(stream, cut, 0);
        INFO("mode " << to_string(mode) << " rpm " << rpm << " cut " << cut);
        CHECK(full.sorted);
        CHECK(full.complete >= static_cast<std::uint64_t>(2 * rpm / 60 - 2));
        for (int lose : {1, 2, 5}) {
          INFO("lose " << lose << " packets at each cut");
          const Result lossy = run(stream, cut, lose);
          // Each revolution lost packets at its start, and its neighbour's at its end: with
          // channels' points reaching across the cut, both frames lack points.
          CHECK(lossy.complete == 0);
          CHECK(lossy.complete + lossy.partial == full.complete + full.partial);
          CHECK(lossy.packets_missing == lossy.packets_lost);
          CHECK(full.packets_missing == 0);
          CHECK(lossy.sorted);
        }
      }
    }
  }
}
