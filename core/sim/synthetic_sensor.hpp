// A simulated Pandar40P: produces valid packets of a chosen kind, deterministically, with no
// hardware. It is the project's embedded default (the demo and `--simulate` run on it) and what
// tests and benchmarks use when they need packets.
//
// The scene is the room of room_scene.hpp (walls, floor, ceiling, a doorway, a pillar and a wire
// fence whose strongest and last echoes differ), shared with the other models' ModelSensor.
// Rays use the calibration's corrected azimuth (block azimuth + offset), so decoding a packet
// with the same calibration puts every point on these surfaces (up to the ±2 raw-unit noise).
//
// Timing follows the time-based trigger: one firing round every 55.56 µs, 1800 packets/s in
// single return and 3600 in dual, azimuth advancing by RPM/60 x 360° x 55.56 µs per round.
// Tail fields are realistic: RPM within ±2 of nominal, µs + UTC date consistent, status id
// cycling 0..22 on a 389 µs time base, factory 0x42, optional UDP sequence counting up.
#pragma once

#include <cstdint>
#include <span>

#include "core/decode/calibration.hpp"
#include "core/sensors/packet.hpp"
#include "core/sim/packet_builder.hpp"

namespace pandarcap {

struct SyntheticSensorConfig {
  int rpm = 600;  // 600 (10 Hz) or 1200 (20 Hz); 60..1500 accepted
  ReturnMode return_mode = ReturnMode::kDual;
  bool udp_sequence = false;  // 1266-byte packets with a sequence number
  std::uint32_t first_sequence = 0;
  std::int64_t start_unix_ns = 1'795'348'800'000'000'000;  // 2026-11-22T12:00:00Z
  double start_azimuth_deg = 0.0;
  std::uint64_t seed = 1;  // varies the distance noise
};

class SyntheticSensor {
 public:
  explicit SyntheticSensor(const SyntheticSensorConfig& config,
                           const Calibration& calibration = Calibration::nominal());

  // Writes the next packet into `out` and returns its size (1262 or 1266).
  std::size_t next(std::span<std::uint8_t, kMaxPacketBytes> out);
  // The contents of the next packet without encoding (tests inspect or alter them).
  PacketContents next_contents();

  // Packet time t0 of the last packet produced, ns since the Unix epoch.
  std::int64_t last_packet_time_ns() const noexcept { return last_t0_ns_; }
  std::uint64_t packets() const noexcept { return packets_; }
  std::int64_t packet_period_ns() const noexcept;
  const SyntheticSensorConfig& config() const noexcept { return config_; }

  // The scene's echo along a ray; 0 raw distance where nothing returns.
  struct Echo {
    std::uint16_t distance_raw = 0;
    std::uint8_t reflectivity = 0;
  };
  struct Echoes {
    Echo strongest, last;
  };
  static Echoes trace(double elevation_deg, double azimuth_deg);

 private:
  SyntheticSensorConfig config_;
  Calibration calibration_;
  std::uint64_t packets_ = 0;
  std::int64_t last_t0_ns_ = 0;
};

}  // namespace pandarcap
