#include "core/sim/synthetic_sensor.hpp"

#include <algorithm>
#include <cmath>

#include "core/decode/packet_time.hpp"
#include "core/sensors/timing.hpp"
#include "core/sim/room_scene.hpp"

namespace pandarcap {

namespace {

constexpr double kStatusPeriodUs = 389.0;  // the status id advances on this time base

// Status word for an id, as real units send it (spec §1.3): numbers for ids 0-7, the firmware
// string "4.3.40a " plus a build id for 8-19 (two ASCII bytes per id, low byte first), "DG" after.
std::uint16_t status_value(int id) {
  static constexpr char kText[] = "4.3.40a 0123456789ABCDEF";  // ids 8..19: 24 characters
  if (id < 8) return static_cast<std::uint16_t>(1900 + 25 * id);
  if (id < 20) {
    const int i = (id - 8) * 2;
    return static_cast<std::uint16_t>(kText[i] | (kText[i + 1] << 8));
  }
  return static_cast<std::uint16_t>('D' | ('G' << 8));
}

}  // namespace

SyntheticSensor::SyntheticSensor(const SyntheticSensorConfig& config,
                                 const Calibration& calibration)
    : config_(config), calibration_(calibration) {
  config_.rpm = std::clamp(config_.rpm, 60, 1500);
}

std::int64_t SyntheticSensor::packet_period_ns() const noexcept {
  return pandarcap::packet_period_ns(config_.return_mode);
}

SyntheticSensor::Echoes SyntheticSensor::trace(double elevation_deg, double azimuth_deg) {
  const RoomEchoes room = trace_room(elevation_deg, azimuth_deg);
  Echoes echoes;
  if (room.last.range_m == 0.0) return echoes;  // nothing returns
  echoes.last = {range_to_raw(room.last.range_m, kDistanceUnitM), room.last.reflectivity};
  echoes.strongest = {range_to_raw(room.strongest.range_m, kDistanceUnitM),
                      room.strongest.reflectivity};
  return echoes;
}

PacketContents SyntheticSensor::next_contents() {
  const ReturnMode mode = config_.return_mode;
  const int rounds = rounds_per_packet(mode);
  const std::uint64_t k = packets_++;
  // Azimuth step per 55.56 µs round, in 0.01°: 600 RPM -> 20.0016.
  const double step_cdeg = config_.rpm / 60.0 * 36000.0 * (kRoundPeriodNs * 1e-9);
  const double start_cdeg = config_.start_azimuth_deg * 100.0;

  PacketContents p;
  for (int r = 0; r < rounds; ++r) {
    const std::uint64_t round = k * static_cast<std::uint64_t>(rounds) + r;
    const double azimuth_cdeg =
        std::fmod(start_cdeg + static_cast<double>(round) * step_cdeg, 36000.0);
    const auto azimuth = static_cast<std::uint16_t>(std::lround(azimuth_cdeg) % 36000);
    const int returns = returns_per_firing(mode);
    for (int echo = 0; echo < returns; ++echo)
      p.azimuth_cdeg[r * returns + echo] = azimuth;
    for (int c = 0; c < kChannels; ++c) {
      // One ray a channel and firing, whatever the echoes taken from it: the trace is most of
      // the simulated sensor's cost (twice over in dual return, when each echo traced it).
      const double alpha = azimuth / 100.0 + calibration_.azimuth_offset_deg[c];
      const Echoes echoes = trace(calibration_.elevation_deg[c], alpha);
      // ±2 raw units (±8 mm) of noise, the same for both echoes of a firing.
      const auto noise = static_cast<int>(scene_hash(config_.seed ^ (round * 64 + c)) % 5) - 2;
      for (int echo = 0; echo < returns; ++echo) {
        const int b = r * returns + echo;
        // Dual: even block = last echo, odd = strongest. Single: the mode's echo.
        const bool want_last =
            mode == ReturnMode::kLast || (mode == ReturnMode::kDual && echo == 0);
        Echo e = want_last ? echoes.last : echoes.strongest;
        if (e.distance_raw != 0) {
          e.distance_raw = static_cast<std::uint16_t>(std::max(1, e.distance_raw + noise));
        }
        p.distance_raw[b][c] = e.distance_raw;
        p.reflectivity[b][c] = e.reflectivity;
      }
    }
  }

  // t0 is taken 28.58 µs after the end of the packet's last round.
  const std::int64_t last_round = static_cast<std::int64_t>(k + 1) * rounds - 1;
  const std::int64_t t0 = config_.start_unix_ns + last_round * kRoundPeriodNs + kLastRoundEndNs;
  last_t0_ns_ = t0;
  const std::int64_t unix_s = t0 / 1'000'000'000;
  Tail& tail = p.tail;
  tail.utc = tail_datetime_from_unix(unix_s);
  tail.timestamp_us = static_cast<std::uint32_t>((t0 % 1'000'000'000) / 1000);
  tail.motor_rpm =
      static_cast<std::uint16_t>(config_.rpm + static_cast<int>(scene_hash(k / 97) % 5) - 2);
  tail.return_mode_byte = static_cast<std::uint8_t>(mode);
  tail.factory = 0x42;
  tail.reserved_opaque[0] = 0x72;
  tail.reserved_opaque[1] = 0x71;
  const double since_start_us = static_cast<double>(t0 - config_.start_unix_ns) / 1000.0;
  tail.status_id =
      static_cast<std::uint8_t>(static_cast<std::int64_t>(since_start_us / kStatusPeriodUs) % 23);
  tail.status_value = status_value(tail.status_id);
  if (config_.udp_sequence) {
    tail.sequence = config_.first_sequence + static_cast<std::uint32_t>(k);
  }
  return p;
}

std::size_t SyntheticSensor::next(std::span<std::uint8_t, kMaxPacketBytes> out) {
  return encode(next_contents(), out);
}

}  // namespace pandarcap
