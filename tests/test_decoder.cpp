// Scalar decoder: geometry, per-point time, range filters and dual-return rules, on crafted
// packets whose expected output is worked out by hand.
#include <catch2/catch.hpp>
#include <cmath>

#include "core/decode/decoder.hpp"
#include "core/sensors/timing.hpp"
#include "core/sim/packet_builder.hpp"

using namespace pandarcap;

namespace {

struct Decoded {
  std::array<Point, kMaxPointsPerPacket> points{};
  DecodedPacket layout;
  FilterCounts filtered;
  std::span<const Point> used() const { return std::span(points).first(layout.point_count); }
};

PacketContents empty_packet(ReturnMode mode, std::uint16_t azimuth = 0) {
  PacketContents p;
  p.azimuth_cdeg.fill(azimuth);
  p.tail.return_mode_byte = static_cast<std::uint8_t>(mode);
  p.tail.motor_rpm = 600;
  p.tail.factory = 0x42;
  p.tail.utc = {17, 9, 6, 16, 19, 46};
  return p;
}

Decoded decode(const PacketContents& contents, const Calibration& calibration,
               DecoderConfig config = {}, std::int64_t t0_ns = 1'000'000'000) {
  std::array<std::uint8_t, kMaxPacketBytes> buffer{};
  const std::size_t size = encode(contents, buffer);
  const auto view = PacketView::make(std::span(buffer).first(size));
  REQUIRE(view.has_value());
  Decoded out;
  ScalarDecoder decoder(calibration, config);
  out.layout = decoder.decode(*view, t0_ns, out.points, out.filtered);
  return out;
}

// A calibration with simple angles: channel 0 at elevation 30°, offset 0; the rest nominal.
Calibration simple_calibration() {
  Calibration c = Calibration::nominal();
  c.elevation_deg[0] = 30.0;
  c.azimuth_offset_deg[0] = 0.0;
  c.source = "test";
  return c;
}

}  // namespace

TEST_CASE("a return at known distance, azimuth and elevation lands at the worked-out xyz",
          "[decoder]") {
  // 10 m at elevation 30°, azimuth 60°: x = 10·cos30·sin60 = 7.5, y = 10·cos30·cos60 = 4.3301,
  // z = 10·sin30 = 5.
  PacketContents p = empty_packet(ReturnMode::kStrongest, 6000);
  p.distance_raw[0][0] = 2500;
  p.reflectivity[0][0] = 77;
  const Decoded d = decode(p, simple_calibration());
  REQUIRE(d.layout.point_count == 1);
  const Point& pt = d.points[0];
  CHECK(pt.x == Approx(7.5).margin(0.001));
  CHECK(pt.y == Approx(4.330127).margin(0.001));
  CHECK(pt.z == Approx(5.0).margin(0.001));
  CHECK(pt.distance_m == Approx(10.0));
  CHECK(pt.intensity == 77);
  CHECK(pt.channel == 0);
  CHECK(pt.azimuth_cdeg == 6000);
  CHECK(pt.return_type == ReturnType::kSingle);
}

TEST_CASE("azimuth 0 points along +y, 90° along +x, clockwise seen from above", "[decoder]") {
  const struct {
    std::uint16_t azimuth;
    float x, y;
  } cases[] = {{0, 0, 4}, {9000, 4, 0}, {18000, 0, -4}, {27000, -4, 0}, {35999, -0.0006981f, 4}};
  Calibration c = simple_calibration();
  c.elevation_deg[0] = 0.0;
  for (const auto& k : cases) {
    PacketContents p = empty_packet(ReturnMode::kLast, k.azimuth);
    p.distance_raw[0][0] = 1000;  // 4 m
    const Decoded d = decode(p, c);
    REQUIRE(d.layout.point_count == 1);
    INFO("azimuth " << k.azimuth);
    CHECK(d.points[0].x == Approx(k.x).margin(0.001));
    CHECK(d.points[0].y == Approx(k.y).margin(0.001));
    CHECK(d.points[0].z == Approx(0).margin(0.001));
  }
}

TEST_CASE("the calibration's azimuth offset is added and wraps around 360°", "[decoder]") {
  // Nominal channel 8 (index 7): elevation 1.33°, offset -5.208°. Block azimuth 2.00° -> 356.792°.
  PacketContents p = empty_packet(ReturnMode::kStrongest, 200);
  p.distance_raw[0][7] = 5000;  // 20 m
  const Decoded d = decode(p, Calibration::nominal());
  REQUIRE(d.layout.point_count == 1);
  const double alpha = 356.792 * M_PI / 180, omega = 1.33 * M_PI / 180;
  CHECK(d.points[0].x == Approx(20 * std::cos(omega) * std::sin(alpha)).margin(0.001));
  CHECK(d.points[0].y == Approx(20 * std::cos(omega) * std::cos(alpha)).margin(0.001));
  CHECK(d.points[0].z == Approx(20 * std::sin(omega)).margin(0.001));
  CHECK(d.points[0].x < 0);  // just left of +y: the offset was added, not subtracted
  CHECK(d.points[0].azimuth_cdeg == 35679);
}

TEST_CASE("firing-time correction rotates each channel back by RPM·6e-6·Δt degrees", "[decoder]") {
  PacketContents p = empty_packet(ReturnMode::kStrongest, 9000);
  p.tail.motor_rpm = 1200;
  p.distance_raw[0][0] = 2500;
  p.distance_raw[0][7] = 2500;
  Calibration c = Calibration::nominal();
  c.azimuth_offset_deg.fill(0.0);
  DecoderConfig config;
  config.firing_time_correction = true;
  const Decoded on = decode(p, c, config);
  const Decoded off = decode(p, c);
  REQUIRE(on.layout.point_count == 2);
  // Channel 8 (index 7) fires 54.67 µs early: 1200 · 6e-6 · 54.67 = 0.3936° -> 89.606°.
  CHECK(off.points[1].azimuth_cdeg == 9000);
  CHECK(on.points[1].azimuth_cdeg == 8961);
  CHECK(on.points[0].azimuth_cdeg == 8970);  // channel 1: 42.22 µs -> 0.304°
  CHECK(on.points[1].y ==
        Approx(10 * std::cos(1.33 * M_PI / 180) * std::cos(89.6064 * M_PI / 180)).margin(0.001));
}

TEST_CASE("every point carries t0 + block offset - channel firing offset", "[decoder]") {
  const std::int64_t t0 = 1'504'714'786'881'567'000;  // 2017-09-06T16:19:46.881567Z
  for (ReturnMode mode : {ReturnMode::kStrongest, ReturnMode::kDual}) {
    PacketContents p = empty_packet(mode, 100);
    for (int b = 0; b < kBlocks; ++b) {
      for (int c = 0; c < kChannels; ++c) {
        // Distinct echoes per block so dual mode keeps both.
        p.distance_raw[b][c] = static_cast<std::uint16_t>(1000 + 100 * (b % 2));
      }
    }
    const Decoded d = decode(p, Calibration::nominal(), {}, t0);
    REQUIRE(d.layout.point_count == 400);
    for (int b = 0; b < kBlocks; ++b) {
      for (std::size_t i = d.layout.block_begin[b]; i < d.layout.block_begin[b + 1]; ++i) {
        const Point& pt = d.points[i];
        CHECK(pt.timestamp_ns ==
              t0 + block_offset_ns(b, mode) - kChannelFiringOffsetNs[pt.channel]);
      }
    }
    // Spot check against the spec's numbers: block 0, channel 8 fires first in the packet.
    const std::int64_t first =
        mode == ReturnMode::kDual ? t0 - 250'820 - 54'670 : t0 - 528'620 - 54'670;
    CHECK(d.points[7].channel == 7);
    CHECK(d.points[7].timestamp_ns == first);
  }
}

TEST_CASE("range filter: 0 is no return, limits are inclusive, counts per reason", "[decoder]") {
  PacketContents p = empty_packet(ReturnMode::kStrongest);
  p.distance_raw[0][0] = 0;      // no return
  p.distance_raw[0][1] = 74;     // 0.296 m < 0.3
  p.distance_raw[0][2] = 75;     // 0.300 m: kept
  p.distance_raw[0][3] = 50000;  // 200.000 m: kept
  p.distance_raw[0][4] = 50001;  // 200.004 m: too far
  p.distance_raw[0][5] = 65535;  // 262.14 m: too far
  const Decoded d = decode(p, Calibration::nominal());
  REQUIRE(d.layout.point_count == 2);
  CHECK(d.points[0].channel == 2);
  CHECK(d.points[1].channel == 3);
  // Every other slot of the packet (10·40 - 6) is also distance 0.
  CHECK(d.filtered[FilterReason::kNoReturn] == 400 - 6 + 1);
  CHECK(d.filtered[FilterReason::kBelowMinRange] == 1);
  CHECK(d.filtered[FilterReason::kAboveMaxRange] == 2);
  CHECK(d.filtered.total() + d.layout.point_count == 400);

  DecoderConfig narrow;
  narrow.min_range_m = 1.0;
  narrow.max_range_m = 100.0;
  const Decoded n = decode(p, Calibration::nominal(), narrow);
  CHECK(n.layout.point_count == 0);
  CHECK(n.filtered[FilterReason::kBelowMinRange] == 2);
  CHECK(n.filtered[FilterReason::kAboveMaxRange] == 3);
}

TEST_CASE("dual return: even block is last, odd is strongest - duplicates merge", "[decoder]") {
  PacketContents p = empty_packet(ReturnMode::kDual, 4500);
  // Pair (0, 1):
  p.distance_raw[0][0] = 2000;  // ch 0: two distinct echoes -> last + strongest
  p.distance_raw[1][0] = 1000;
  p.distance_raw[0][1] = 1500;  // ch 1: byte-identical -> one point, odd block's copy
  p.reflectivity[0][1] = 9;
  p.distance_raw[1][1] = 1500;
  p.reflectivity[1][1] = 9;
  p.distance_raw[0][2] = 1524;  // ch 2: 0.096 m apart < 0.1 m -> merged
  p.distance_raw[1][2] = 1500;
  p.distance_raw[0][3] = 1525;  // ch 3: 0.100 m apart -> both kept
  p.distance_raw[1][3] = 1500;
  p.distance_raw[0][4] = 0;  // ch 4: only the strongest echo
  p.distance_raw[1][4] = 800;
  p.distance_raw[0][5] = 900;  // ch 5: only the last echo
  p.distance_raw[1][5] = 0;
  p.distance_raw[0][6] = 1500;  // ch 6: same distance, other reflectivity -> merged (too close)
  p.reflectivity[0][6] = 1;
  p.distance_raw[1][6] = 1500;
  p.reflectivity[1][6] = 2;
  const Decoded d = decode(p, Calibration::nominal());

  auto find = [&](int block, int channel) -> const Point* {
    for (std::size_t i = d.layout.block_begin[block]; i < d.layout.block_begin[block + 1]; ++i) {
      if (d.points[i].channel == channel) return &d.points[i];
    }
    return nullptr;
  };
  REQUIRE(find(0, 0) != nullptr);
  CHECK(find(0, 0)->return_type == ReturnType::kLast);
  CHECK(find(0, 0)->distance_m == Approx(8.0));
  REQUIRE(find(1, 0) != nullptr);
  CHECK(find(1, 0)->return_type == ReturnType::kStrongest);
  CHECK(find(1, 0)->distance_m == Approx(4.0));

  CHECK(find(0, 1) == nullptr);
  REQUIRE(find(1, 1) != nullptr);
  CHECK(find(1, 1)->return_type == ReturnType::kLastStrongest);

  CHECK(find(0, 2) == nullptr);
  REQUIRE(find(1, 2) != nullptr);
  CHECK(find(1, 2)->return_type == ReturnType::kLastStrongest);

  CHECK(find(0, 3) != nullptr);
  CHECK(find(1, 3) != nullptr);

  CHECK(find(0, 4) == nullptr);
  REQUIRE(find(1, 4) != nullptr);
  CHECK(find(1, 4)->return_type == ReturnType::kStrongest);

  REQUIRE(find(0, 5) != nullptr);
  CHECK(find(0, 5)->return_type == ReturnType::kLast);
  CHECK(find(1, 5) == nullptr);

  CHECK(find(0, 6) == nullptr);
  CHECK(find(1, 6) != nullptr);

  CHECK(d.filtered[FilterReason::kDualDuplicate] == 1);
  CHECK(d.filtered[FilterReason::kDualTooClose] == 2);
  CHECK(d.layout.point_count == 9);
  CHECK(d.filtered.total() + d.layout.point_count == 400);
  // Both blocks of a pair share the firing time.
  CHECK(find(0, 0)->timestamp_ns == find(1, 0)->timestamp_ns);
}

TEST_CASE("the dual threshold is configurable - 0 keeps every non-identical pair", "[decoder]") {
  PacketContents p = empty_packet(ReturnMode::kDual);
  p.distance_raw[0][0] = 1501;
  p.distance_raw[1][0] = 1500;
  DecoderConfig config;
  config.dual_return_distance_threshold_m = 0.0;
  CHECK(decode(p, Calibration::nominal(), config).layout.point_count == 2);
  config.dual_return_distance_threshold_m = 0.1;
  CHECK(decode(p, Calibration::nominal(), config).layout.point_count == 1);
}

TEST_CASE("block layout groups points by block in block order", "[decoder]") {
  PacketContents p = empty_packet(ReturnMode::kStrongest);
  for (int b = 0; b < kBlocks; ++b) {
    p.azimuth_cdeg[b] = static_cast<std::uint16_t>(1000 + 20 * b);
    for (int c = 0; c <= b; ++c)
      p.distance_raw[b][c] = 1000;  // block b has b + 1 points
  }
  const Decoded d = decode(p, Calibration::nominal());
  CHECK(d.layout.point_count == 55);
  for (int b = 0; b < kBlocks; ++b) {
    CHECK(d.layout.block_begin[b + 1] - d.layout.block_begin[b] == b + 1);
  }
}
