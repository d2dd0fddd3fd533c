// The simulated sensor: valid packets with realistic timing and tail fields, and a scene that the
// decoder must reconstruct. The ray tracer computes ranges from plane intersections; the decoder
// turns ranges back into xyz; points landing on the scene's surfaces check elevation, azimuth
// offsets and the axis convention from the other direction.
#include <catch2/catch.hpp>
#include <cmath>
#include <set>

#include "core/decode/decoder.hpp"
#include "core/decode/packet_time.hpp"
#include "core/sensors/timing.hpp"
#include "core/sim/synthetic_sensor.hpp"

using namespace pandarcap;

TEST_CASE("synthetic packets are valid with realistic tails and timing", "[synthetic]") {
  for (int rpm : {600, 1200}) {
    for (ReturnMode mode : {ReturnMode::kDual, ReturnMode::kStrongest, ReturnMode::kLast}) {
      for (bool sequence : {false, true}) {
        SyntheticSensorConfig config;
        config.rpm = rpm;
        config.return_mode = mode;
        config.udp_sequence = sequence;
        config.first_sequence = 0xFFFFFFF0;
        SyntheticSensor sensor(config);
        PacketClock clock;
        std::array<std::uint8_t, kMaxPacketBytes> buffer{};
        std::int64_t previous_t0 = 0;
        std::set<int> status_ids;
        const int packets = mode == ReturnMode::kDual ? 3600 : 1800;  // one second
        for (int k = 0; k < packets; ++k) {
          const std::size_t size = sensor.next(buffer);
          CHECK(size == (sequence ? 1266u : 1262u));
          const auto view = PacketView::make(std::span(buffer).first(size));
          REQUIRE(view.has_value());
          const Tail tail = view->tail();
          CHECK(view->return_mode() == mode);
          CHECK(std::abs(tail.motor_rpm - rpm) <= 2);
          CHECK(tail.factory == 0x42);
          status_ids.insert(tail.status_id);
          if (sequence) CHECK(tail.sequence == std::optional<std::uint32_t>(0xFFFFFFF0u + k));
          const PacketTime t = clock.convert(tail.utc, tail.timestamp_us);
          REQUIRE(t.valid());
          CHECK(t.t0_ns / 1000 == sensor.last_packet_time_ns() / 1000);
          if (k > 0) CHECK(t.t0_ns - previous_t0 == Approx(packet_period_ns(mode)).margin(1000));
          previous_t0 = t.t0_ns;
          // Azimuth advances by RPM/60 * 360° * 55.56 µs per firing round: 0.2° at 600 RPM.
          const int step = rpm / 30;  // 0.01° per round: 20 at 600 RPM, 40 at 1200
          const int pairs = returns_per_firing(mode);
          for (int b = pairs; b < kBlocks; b += pairs) {
            const int d = (view->azimuth_cdeg(b) - view->azimuth_cdeg(b - pairs) + 36000) % 36000;
            CHECK(std::abs(d - step) <= 1);
          }
          if (mode == ReturnMode::kDual) {
            for (int b = 0; b < kBlocks; b += 2)
              CHECK(view->azimuth_cdeg(b) == view->azimuth_cdeg(b + 1));
          }
        }
        CHECK(status_ids.size() == 23);
      }
    }
  }
}

TEST_CASE("decoded synthetic points lie on the scene's surfaces", "[synthetic][geometry]") {
  SyntheticSensorConfig config;
  config.return_mode = ReturnMode::kDual;
  SyntheticSensor sensor(config);
  const ScalarDecoder decoder(Calibration::nominal(), {});
  std::array<std::uint8_t, kMaxPacketBytes> buffer{};
  std::array<Point, kMaxPointsPerPacket> points{};
  FilterCounts filtered;
  std::size_t floor = 0, ceiling = 0, walls = 0, pillar = 0, fence = 0;
  for (int k = 0; k < 360; ++k) {  // one revolution
    const std::size_t size = sensor.next(buffer);
    const auto view = PacketView::make(std::span(buffer).first(size));
    REQUIRE(view.has_value());
    const DecodedPacket d = decoder.decode(*view, 0, points, filtered);
    for (std::size_t i = 0; i < d.point_count; ++i) {
      const Point& p = points[i];
      // Range noise is ±8 mm; 0.01° azimuth rounding adds up to 3 mm at 18 m.
      constexpr double kTol = 0.015;
      INFO("point x=" << p.x << " y=" << p.y << " z=" << p.z << " refl=" << int(p.intensity));
      switch (p.intensity) {
        case 20:
          CHECK(p.z == Approx(-1.8).margin(kTol));
          ++floor;
          break;
        case 40:
          CHECK(p.z == Approx(3.0).margin(kTol));
          ++ceiling;
          break;
        case 60: {
          const bool on_wall = std::abs(p.x - 18) < kTol || std::abs(p.x + 12) < kTol ||
                               std::abs(p.y - 9) < kTol || std::abs(p.y + 7) < kTol;
          CHECK(on_wall);
          ++walls;
          break;
        }
        case 200:
          CHECK(std::hypot(p.x - 5.0, p.y - 3.0) == Approx(0.5).margin(kTol));
          ++pillar;
          break;
        case 120:
          CHECK(p.x == Approx(4.0).margin(kTol));
          // At the fence's foot the floor behind it is within 0.1 m: the echoes merge.
          CHECK(p.return_type != ReturnType::kLast);
          ++fence;
          break;
        default:
          FAIL("unexpected reflectivity");
      }
    }
  }
  CHECK(floor > 1000);
  CHECK(ceiling > 1000);
  CHECK(walls > 1000);
  CHECK(pillar > 100);
  CHECK(fence > 100);
  // The doorway returns nothing, so some slots are "no return".
  CHECK(filtered[FilterReason::kNoReturn] > 100);
}
