// A simulated Pandar64, PandarXT32, PandarXT16 or PandarQT128: valid packets of the model, built
// from the same room as the Pandar40P's SyntheticSensor (room_scene.hpp), deterministically and
// with no hardware, so that tests, benchmarks and `--simulate` can run every model pandarcap
// decodes. The layouts are the model headers' (core/sensors/); what each byte holds is
// /work/research/hesai-models.md §1-§3.
//
// Timing follows the model's time-based trigger (model_facts.hpp): a firing every
// Model::kFiringPeriodNs whatever the speed, `returns` blocks per firing (one per echo), so a
// packet every Model::packet_period_ns(returns); the azimuth advances by
// Model::azimuth_step_per_firing_cdeg(rpm) per firing and the blocks of one firing share it. The
// packet time is the one the model's firing_offset_ns() puts the firings at: firing f of the
// stream is the config's start time + f × the firing period.
//
// Each ray uses the calibration's corrected azimuth (block azimuth + offset) and elevation, so
// decoding with the same calibration puts every point on the room's surfaces (up to ±2 raw units
// of noise, 4 mm each, the same for all echoes of a firing). In a dual mode the fence gives two
// different echoes, elsewhere both blocks of a firing are identical, as on real sensors.
//
// Per model:
//   Pandar64   header EE FF 40 06, unit 4 mm; the 40P's tail (year byte by the SDK rule:
//              < 70 from 2000); the UDP sequence (1198 bytes) when `udp_sequence` is set.
//   PandarXT   header EE FF 06 01, N lasers, 8 blocks, echo byte, unit 4 mm, echo count, flags
//              0x01; confidence 255; year from 1900; the UDP sequence always (the protocol's).
//   PandarQT128  flags: functional safety | confidence, | sequence when `udp_sequence` (1095 or
//              1091 bytes; no signature); the FS block's rolling counter counts packets; the
//              tail's mode flag says which firing sequence the packet's first firing is: firings
//              alternate sequence 1 and 2 (so the flag alternates every packet in dual and stays
//              1 in single), and a channel not in its firing's sequence carries distance 0; the
//              three CRCs written by PandarQT128::write_crcs.
// Tail everywhere: motor speed within ±2 RPM of nominal, µs + UTC date of the packet time,
// return mode, factory 0x42, high temperature 0.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>

#include "core/decode/calibration.hpp"
#include "core/sensors/packet.hpp"
#include "core/sensors/sensor_models.hpp"

namespace pandarcap {

struct ModelSensorConfig {
  int rpm = 600;                               // one of the model's kSupportedRpms
  ReturnMode return_mode = ReturnMode::kDual;  // one of the model's kReturnModes
  bool udp_sequence = false;                   // Pandar64 and QT128; the XT always has one
  std::uint32_t first_sequence = 0;            // the first packet's UDP sequence
  std::int64_t start_unix_ns = 1'795'348'800'000'000'000;  // 2026-11-22T12:00:00Z
  double start_azimuth_deg = 0.0;
  std::uint64_t seed = 1;  // varies the distance noise
};

// Model: Pandar64, PandarXT32, PandarXT16 or PandarQT128 (the Pandar40P's is SyntheticSensor).
template <class Model>
class ModelSensor {
 public:
  // Throws std::invalid_argument for a speed or return mode the model does not have, or a
  // calibration whose channel count is not the model's.
  explicit ModelSensor(const ModelSensorConfig& config,
                       const Calibration& calibration = Calibration::nominal(Model::kId));

  // Writes the next datagram into `out` and returns its size (datagram_bytes()). Throws
  // std::invalid_argument when `out` is shorter (Model::kMaxDatagramBytes always suffices).
  std::size_t next(std::span<std::uint8_t> out);

  // The size of every datagram this sensor writes.
  std::size_t datagram_bytes() const noexcept { return datagram_bytes_; }
  // Packet time of the last packet produced, ns since the Unix epoch.
  std::int64_t last_packet_time_ns() const noexcept { return last_t0_ns_; }
  std::uint64_t packets() const noexcept { return packets_; }
  std::int64_t packet_period_ns() const noexcept { return Model::packet_period_ns(returns_); }
  const ModelSensorConfig& config() const noexcept { return config_; }
  const Calibration& calibration() const noexcept { return calibration_; }

 private:
  ModelSensorConfig config_;
  Calibration calibration_;
  int returns_ = 1;
  std::size_t datagram_bytes_ = 0;
  std::uint64_t packets_ = 0;
  std::int64_t last_t0_ns_ = 0;
};

extern template class ModelSensor<Pandar64>;
extern template class ModelSensor<PandarXT32>;
extern template class ModelSensor<PandarXT16>;
extern template class ModelSensor<PandarQT128>;

}  // namespace pandarcap
