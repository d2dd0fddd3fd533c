// The simulated Pandar64, PandarXT32, PandarXT16 and PandarQT128 (core/sim/model_sensor.hpp):
// for every model, return mode and sequence setting, every packet is one its model accepts and
// detection names, its time moves by the model's packet period, its azimuth by the model's step,
// a revolution at 600 RPM takes the model's packets per revolution, and the tail says what the
// config asked. Points are decoded here with this file's own arithmetic (distance × the header's
// unit, the calibration's elevation and azimuth, x = d cos ω sin α, y = d cos ω cos α,
// z = d sin ω: hesai-models.md §4.2), not the project's decoder, and must lie on the room's
// surfaces. AnyModelSensor picks the right simulator, and its Pandar40P is SyntheticSensor's.
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <catch2/catch.hpp>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include "core/decode/packet_time.hpp"
#include "core/sensors/model_detection.hpp"
#include "core/sensors/sensor_models.hpp"
#include "core/sim/any_model_sensor.hpp"
#include "core/sim/model_sensor.hpp"
#include "core/sim/room_scene.hpp"
#include "core/sim/simulated_unit.hpp"
#include "core/sim/synthetic_sensor.hpp"

using namespace pandarcap;

namespace {

using Buffer = std::array<std::uint8_t, kLargestDatagramBytes>;

template <class F>
void for_each_simulated_model(F&& f) {
  f(std::type_identity<Pandar64>{});
  f(std::type_identity<PandarXT32>{});
  f(std::type_identity<PandarXT16>{});
  f(std::type_identity<PandarQT128>{});
}

// The packet time its tail says, ns (µs resolution).
template <class M>
std::int64_t tail_time_ns(std::span<const std::uint8_t> p) {
  const PacketDateTime d = M::utc(p);
  const std::int64_t seconds =
      days_from_civil(d.year, d.month, d.day) * 86'400 + d.hour * 3600 + d.minute * 60 + d.second;
  return seconds * 1'000'000'000 + static_cast<std::int64_t>(M::timestamp_us(p)) * 1000;
}

// The azimuth difference b - a in 0.01°, wrapped into -18000..17999.
int azimuth_delta(int a, int b) {
  return ((b - a) % 36000 + 54000) % 36000 - 18000;
}

struct Xyz {
  double x, y, z;
};

Xyz to_xyz(double distance_m, double elevation_deg, double azimuth_deg) {
  constexpr double kRad = std::numbers::pi / 180.0;
  const double w = elevation_deg * kRad, a = azimuth_deg * kRad;
  return {distance_m * std::cos(w) * std::sin(a), distance_m * std::cos(w) * std::cos(a),
          distance_m * std::sin(w)};
}

// Whether a point of this reflectivity lies on its surface of the room, within `tol` metres.
bool on_room_surface(const Xyz& p, std::uint8_t reflectivity, double tol) {
  switch (reflectivity) {
    case room::kFloorReflectivity:
      return std::abs(p.z - room::kFloorZ) < tol;
    case room::kCeilingReflectivity:
      return std::abs(p.z - room::kCeilingZ) < tol;
    case room::kWallReflectivity:
      return std::abs(p.x - room::kWallXMax) < tol || std::abs(p.x - room::kWallXMin) < tol ||
             std::abs(p.y - room::kWallYMax) < tol || std::abs(p.y - room::kWallYMin) < tol;
    case room::kPillarReflectivity:
      return std::abs(std::hypot(p.x - room::kPillarX, p.y - room::kPillarY) -
                      room::kPillarRadius) < tol;
    case room::kFenceReflectivity:
      return std::abs(p.x - room::kFenceX) < tol && p.y > room::kFenceYMin - tol &&
             p.y < room::kFenceYMax + tol;
    default:
      return false;
  }
}

template <class M>
std::size_t expected_size(bool sequence) {
  if constexpr (std::is_same_v<M, PandarQT128>) {
    return sequence ? 1095 : 1091;  // FS + confidence (+ sequence), no signature: §1.1's table
  } else if constexpr (std::is_same_v<M, Pandar64>) {
    return sequence ? 1198 : 1194;
  } else {
    return M::kChannels == 32 ? 1080 : 568;  // the XT always carries its sequence
  }
}

// The tail's raw year byte (each model has its own rule for it).
template <class M>
std::uint8_t raw_year_byte(std::span<const std::uint8_t> p) {
  if constexpr (std::is_same_v<M, PandarQT128>) {
    return PandarQT128::tail(p)[PandarQT128::kDateTimeInTail];
  } else {
    return p[M::kDateTimeOffset];
  }
}

}  // namespace

TEST_CASE("simulated models: valid, detected, timed and turning as the model, every mode",
          "[sim][sensors]") {
  for_each_simulated_model([]<class M>(std::type_identity<M>) {
    for (const int rpm : M::kSupportedRpms) {
      for (const ReturnMode mode : M::kReturnModes) {
        // Every mode at 600 RPM; the other speed in the default mode.
        if (rpm != 600 && mode != ReturnMode::kDual) continue;
        for (const bool sequence : {false, true}) {
          INFO(display_name(M::kId)
               << " " << rpm << " RPM " << to_string(mode) << " sequence " << sequence);
          ModelSensorConfig config;
          config.rpm = rpm;
          config.return_mode = mode;
          config.udp_sequence = sequence;
          config.first_sequence = 0xFFFFFFFE;  // wraps on the third packet
          config.start_azimuth_deg = 350.0;    // wraps within the first revolution's tenth
          ModelSensor<M> sensor(config);
          const int returns = returns_per_firing(mode);
          const double ppr = M::packets_per_revolution(returns, rpm);
          const double step = M::azimuth_step_per_firing_cdeg(rpm);
          const double packet_step = M::azimuth_step_per_packet_cdeg(returns, rpm);
          REQUIRE(sensor.packet_period_ns() == M::packet_period_ns(returns));
          Buffer buffer{};
          // Two revolutions and a tenth for one single and one dual mode with the sequence (the
          // rates depend on the echo count alone); the others, whose tails and echoes alone
          // differ, a few packets.
          const bool whole_turns =
              sequence && (mode == ReturnMode::kDual || mode == ReturnMode::kLast);
          const int count = whole_turns ? static_cast<int>(std::ceil(ppr * 2.1)) : 64;
          std::int64_t previous_time = 0;
          int previous_azimuth = -1, last_wrap = -1, wraps = 0;
          std::vector<int> revolution_lengths;
          // Per-packet checks counted, not asserted one by one: the first few failures are kept.
          int failures = 0;
          std::string first_failures;
          const auto expect = [&](bool ok, int k, const char* what) {
            if (ok) return;
            if (++failures <= 5) first_failures += fmt::format("packet {}: {}; ", k, what);
          };
          for (int k = 0; k < count; ++k) {
            const std::size_t size = sensor.next(buffer);
            REQUIRE(size == expected_size<M>(sequence));
            const std::span<const std::uint8_t> p(buffer.data(), size);
            const DetectedModel detected = detect_model(p);
            if (M::validate(p) != RejectReason::kNone || detected.kind != DetectionKind::kKnown ||
                detected.model != M::kId) {
              expect(false, k, "not valid or not detected as the model");
              continue;
            }
            // Tail: what the config asked and the time the sensor says.
            expect(M::return_mode(p) == mode, k, "return mode");
            expect(std::abs(M::motor_rpm(p) - rpm) <= 2, k, "motor speed");
            expect(M::factory(p) == 0x42, k, "factory");
            expect(!M::high_temperature(p), k, "high temperature");
            expect(M::distance_unit_m(p) == 0.004, k, "distance unit");
            expect(M::utc(p).year == 2026, k, "year");
            // The Pandar64 counts a year byte below 70 from 2000, the XT and QT128 from 1900.
            expect(raw_year_byte<M>(p) == (std::is_same_v<M, Pandar64> ? 26 : 126), k,
                   "raw year byte");
            expect(tail_time_ns<M>(p) == sensor.last_packet_time_ns() / 1000 * 1000, k,
                   "tail time");
            const bool has_sequence = sequence || M::kId == SensorModelId::kPandarXT32 ||
                                      M::kId == SensorModelId::kPandarXT16;
            expect(has_sequence ? M::sequence(p) == static_cast<std::uint32_t>(0xFFFFFFFEu + k)
                                : !M::sequence(p).has_value(),
                   k, "UDP sequence");
            expect(k == 0 ||
                       sensor.last_packet_time_ns() - previous_time == M::packet_period_ns(returns),
                   k, "packet period");
            previous_time = sensor.last_packet_time_ns();
            // Azimuth: the blocks of a firing share it, firings step by `step`, packets by
            // `packet_step` (each rounded to 0.01°).
            for (int b = 1; b < M::kBlocks; ++b) {
              const int a = M::azimuth_cdeg(p, b);
              expect(b % returns != 0 ? a == M::azimuth_cdeg(p, b - 1)
                                      : std::abs(azimuth_delta(M::azimuth_cdeg(p, b - returns), a) -
                                                 step) <= 1.0,
                     k, "block azimuth");
            }
            const int azimuth = M::azimuth_cdeg(p, 0);
            if (previous_azimuth >= 0) {
              expect(std::abs(azimuth_delta(previous_azimuth, azimuth) - packet_step) <= 1.0, k,
                     "packet azimuth step");
              if (azimuth < previous_azimuth) {  // wrapped past 0°
                if (last_wrap >= 0) revolution_lengths.push_back(k - last_wrap);
                last_wrap = k;
                ++wraps;
              }
            }
            previous_azimuth = azimuth;
          }
          INFO(first_failures);
          CHECK(failures == 0);
          if (!whole_turns) continue;
          CHECK(wraps == 3);  // 350°, then two revolutions and a tenth
          // A revolution takes the model's packets per revolution (a non-integer count rounds
          // to its neighbours).
          REQUIRE(revolution_lengths.size() == 2);
          for (const int n : revolution_lengths) {
            CHECK(n >= static_cast<int>(std::floor(ppr)));
            CHECK(n <= static_cast<int>(std::ceil(ppr)));
          }
        }
      }
    }
  });
}

TEST_CASE("simulated models' points, decoded here, lie on the room's surfaces", "[sim][sensors]") {
  for_each_simulated_model([]<class M>(std::type_identity<M>) {
    // A unit's own table (0.4° and 0.2° away from the nominal one at most), so that a ray not
    // using it would miss.
    const Calibration unit = simulated_unit_calibration(M::kId);
    for (const Calibration& calibration : {Calibration::nominal(M::kId), unit}) {
      INFO(display_name(M::kId) << " calibration "
                                << (calibration.is_nominal() ? "nominal" : "unit"));
      ModelSensorConfig config;  // dual: last + strongest
      ModelSensor<M> sensor(config, calibration);
      Buffer buffer{};
      const int per_revolution =
          static_cast<int>(std::ceil(M::packets_per_revolution(2, config.rpm)));
      int points = 0, off_surface = 0, off_at_nominal = 0, fence_pairs = 0, other_pairs = 0;
      std::array<int, 256> by_reflectivity{};
      for (int k = 0; k < per_revolution; ++k) {
        const std::size_t size = sensor.next(buffer);
        const std::span<const std::uint8_t> p(buffer.data(), size);
        REQUIRE(M::validate(p) == RejectReason::kNone);
        // The unit from the header byte (4 mm), as a decoder reads it.
        const std::uint8_t unit_mm = std::is_same_v<M, Pandar64> ? p[5] : p[9];
        REQUIRE(unit_mm == 4);
        for (int b = 0; b < M::kBlocks; ++b) {
          for (int c = 0; c < M::kChannels; ++c) {
            const std::uint16_t raw = M::distance_raw(p, b, c);
            if (raw == 0) continue;
            const auto ch = static_cast<std::size_t>(c);
            const Xyz xyz =
                to_xyz(raw * unit_mm * 1e-3, calibration.elevation_deg[ch],
                       M::azimuth_cdeg(p, b) / 100.0 + calibration.azimuth_offset_deg[ch]);
            const std::uint8_t r = M::reflectivity(p, b, c);
            ++points;
            ++by_reflectivity[r];
            // ±8 mm noise and 2 mm range rounding.
            if (!on_room_surface(xyz, r, 0.012)) ++off_surface;
            // The same range at the nominal angles: off the surfaces where the unit's table
            // moved the ray (so the rays did use the table they were given).
            const Xyz at_nominal =
                to_xyz(raw * unit_mm * 1e-3, M::kNominalElevationDeg[ch],
                       M::azimuth_cdeg(p, b) / 100.0 + M::kNominalAzimuthOffsetDeg[ch]);
            if (!on_room_surface(at_nominal, r, 0.012)) ++off_at_nominal;
            if (b % 2 == 1 && raw != M::distance_raw(p, b - 1, c)) {
              // A dual pair's echoes differ only at the fence: strongest the fence, last behind.
              if (r == room::kFenceReflectivity &&
                  M::reflectivity(p, b - 1, c) != room::kFenceReflectivity &&
                  raw < M::distance_raw(p, b - 1, c)) {
                ++fence_pairs;
              } else {
                ++other_pairs;
              }
            }
          }
        }
      }
      CHECK(points > per_revolution * M::kMaxPointsPerPacket / 4);
      CHECK(off_surface == 0);
      if (calibration.is_nominal()) {
        CHECK(off_at_nominal == 0);
      } else {
        CHECK(off_at_nominal > points / 4);  // near ranges move less than 12 mm
      }
      CHECK(fence_pairs > 10);
      CHECK(other_pairs == 0);
      for (const std::uint8_t r : {room::kFloorReflectivity, room::kWallReflectivity,
                                   room::kPillarReflectivity, room::kFenceReflectivity}) {
        CHECK(by_reflectivity[r] > 0);
      }
    }
  });
}

TEST_CASE("simulated QT128: firing sequences by the mode flag, and CRCs a flipped byte breaks",
          "[sim][sensors]") {
  for (const ReturnMode mode : {ReturnMode::kDual, ReturnMode::kStrongest}) {
    INFO(to_string(mode));
    ModelSensorConfig config;
    config.return_mode = mode;
    config.udp_sequence = true;
    ModelSensor<PandarQT128> sensor(config);
    Buffer buffer{};
    for (int k = 0; k < 40; ++k) {
      const std::size_t size = sensor.next(buffer);
      const std::span<std::uint8_t> p(buffer.data(), size);
      REQUIRE(PandarQT128::validate(p) == RejectReason::kNone);
      // Firings alternate sequence 1 and 2: a dual packet is one firing, so its flag alternates;
      // a single one is two, so its first is always sequence 1 (flag 1).
      const std::uint8_t flag = PandarQT128::mode_flag(p);
      CHECK(flag == (mode == ReturnMode::kDual ? (k % 2 == 0 ? 1 : 0) : 1));
      // hesai-models.md §2.4: channels 32-63 are 0 in sequence 2, channels 0-31 in sequence 1.
      for (int b = 0; b < 2; ++b) {
        const bool sequence_1 = mode == ReturnMode::kDual ? flag == 1 : b == 0;
        int silent = 0, firing_zero = 0;
        for (int c = 0; c < 64; ++c) {
          const bool fires = sequence_1 ? c >= 32 : c < 32;
          if (!fires) silent += PandarQT128::distance_raw(p, b, c) == 0 ? 1 : 0;
          if (fires) firing_zero += PandarQT128::distance_raw(p, b, c) == 0 ? 1 : 0;
        }
        CHECK(silent == 32);
        CHECK(firing_zero < 32);  // those that fire mostly see the room
      }
      CHECK(PandarQT128::functional_safety_state(p) == 0);
      if (k == 7) {
        const PandarQT128::Layout l = PandarQT128::layout(p);
        for (const std::size_t at : {std::size_t{200}, *l.functional_safety_offset + 3,
                                     l.tail_offset + PandarQT128::kMotorSpeedInTail,
                                     *l.sequence_offset, l.tail_crc_offset + 1}) {
          INFO("flipped byte " << at);
          p[at] ^= 0x01;
          CHECK(PandarQT128::validate(p) == RejectReason::kBadCrc);
          CHECK(detect_model(p).reject == RejectReason::kBadCrc);
          p[at] ^= 0x01;
          CHECK(PandarQT128::validate(p) == RejectReason::kNone);
        }
      }
    }
  }
}

TEST_CASE("simulated models refuse what the model does not have", "[sim][sensors]") {
  ModelSensorConfig qt;
  qt.rpm = 1200;
  CHECK_THROWS_WITH(ModelSensor<PandarQT128>(qt),
                    "a simulated PandarQT128 spins at 600 RPM, not 1200");
  ModelSensorConfig first;
  first.return_mode = ReturnMode::kFirst;
  CHECK_THROWS_WITH(ModelSensor<Pandar64>(first),
                    "a simulated Pandar64 sends strongest, last, dual return, not 'first'");
  CHECK_NOTHROW(ModelSensor<PandarXT32>(first));
  CHECK_THROWS_WITH(ModelSensor<PandarXT16>({}, Calibration::nominal(SensorModelId::kPandarXT32)),
                    "a PandarXT16 calibration has 16 channels, not 32");
  ModelSensor<PandarXT32> xt({});
  std::array<std::uint8_t, 1079> short_buffer{};
  CHECK_THROWS_AS(xt.next(short_buffer), std::invalid_argument);
  CHECK(xt.packets() == 0);
}

TEST_CASE("AnyModelSensor: the model's simulator by id, its Pandar40P SyntheticSensor's bytes",
          "[sim][sensors]") {
  for (const SensorModelId id : kSensorModelIds) {
    INFO(display_name(id));
    ModelSensorConfig config;
    config.udp_sequence = true;
    AnyModelSensor sensor(id, config);
    CHECK(sensor.model() == id);
    const std::int64_t period =
        with_model(id, []<class M>(std::type_identity<M>) { return M::packet_period_ns(2); });
    CHECK(sensor.packet_period_ns() == period);
    Buffer buffer{};
    for (int k = 0; k < 3; ++k) {
      const std::size_t size = sensor.next(buffer);
      CHECK(size == sensor.max_datagram_bytes());
      const DetectedModel detected = detect_model(std::span(buffer.data(), size));
      CHECK(detected.kind == DetectionKind::kKnown);
      CHECK(detected.model == id);
    }
    CHECK(sensor.packets() == 3);
  }
  // The 40P: byte for byte SyntheticSensor with the same settings.
  ModelSensorConfig config;
  config.return_mode = ReturnMode::kLast;
  config.seed = 9;
  config.start_azimuth_deg = 123.4;
  AnyModelSensor any(SensorModelId::kPandar40P, config);
  SyntheticSensorConfig sc;
  sc.return_mode = ReturnMode::kLast;
  sc.seed = 9;
  sc.start_azimuth_deg = 123.4;
  SyntheticSensor synthetic(sc);
  for (int k = 0; k < 20; ++k) {
    Buffer a{}, b{};
    const std::size_t na = any.next(a);
    REQUIRE(na == synthetic.next(std::span(b).first<kMaxPacketBytes>()));
    CHECK(std::equal(a.begin(), a.begin() + static_cast<long>(na), b.begin()));
    CHECK(any.last_packet_time_ns() == synthetic.last_packet_time_ns());
  }
  ModelSensorConfig bad;
  bad.rpm = 1200;
  CHECK_THROWS_AS(AnyModelSensor(SensorModelId::kPandarQT128, bad), std::invalid_argument);
  CHECK_THROWS_AS(
      AnyModelSensor(SensorModelId::kPandar40P, {}, Calibration::nominal(SensorModelId::kPandar64)),
      std::invalid_argument);
}

TEST_CASE("a simulated unit's table for every model: the 40P's as its PTC serves, CSV round trip",
          "[sim][sensors]") {
  const Calibration served = simulated_unit().calibration;
  const Calibration forty = simulated_unit_calibration(SensorModelId::kPandar40P);
  CHECK(forty.elevation_deg == served.elevation_deg);
  CHECK(forty.azimuth_offset_deg == served.azimuth_offset_deg);
  for (const SensorModelId id : kSensorModelIds) {
    INFO(display_name(id));
    const Calibration unit = simulated_unit_calibration(id);
    const Calibration nominal = Calibration::nominal(id);
    REQUIRE(unit.channel_count == channel_count(id));
    CHECK(unit.source == "simulated unit");
    double most_elevation = 0, most_azimuth = 0;
    for (std::size_t c = 0; c < static_cast<std::size_t>(unit.channel_count); ++c) {
      most_elevation =
          std::max(most_elevation, std::abs(unit.elevation_deg[c] - nominal.elevation_deg[c]));
      most_azimuth = std::max(most_azimuth,
                              std::abs(unit.azimuth_offset_deg[c] - nominal.azimuth_offset_deg[c]));
    }
    // Within the pattern's 0.40° / 0.20° (and the rounding to three decimals), and using it.
    CHECK(most_elevation <= 0.4006);
    CHECK(most_elevation > 0.3);
    CHECK(most_azimuth <= 0.2006);
    CHECK(most_azimuth > 0.15);
    const Calibration parsed = Calibration::parse(unit.to_csv(), "served", id);
    CHECK(parsed.elevation_deg == unit.elevation_deg);
    CHECK(parsed.azimuth_offset_deg == unit.azimuth_offset_deg);
  }
}
