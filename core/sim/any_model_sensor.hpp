// A simulated sensor of any supported model, chosen at run time: what `pandarcapd --simulate
// --sensor-model M` and `pandarcap-bench send --sensor-model M` hold. The Pandar40P is its
// SyntheticSensor (byte for byte what it always sent), the others their ModelSensor; the model
// is chosen once, at construction, and each next() is one switch on a variant, no allocation.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <variant>

#include "core/decode/calibration.hpp"
#include "core/sensors/sensor_model_id.hpp"
#include "core/sim/model_sensor.hpp"
#include "core/sim/synthetic_sensor.hpp"

namespace pandarcap {

// The same settings in the other simulator's terms (the 40P's SyntheticSensor and the others'
// ModelSensor take the same fields).
SyntheticSensorConfig synthetic_sensor_config(const ModelSensorConfig& config);
ModelSensorConfig model_sensor_config(const SyntheticSensorConfig& config);

class AnyModelSensor {
 public:
  // `calibration`: the table the rays use (default: the model's nominal one). Throws
  // std::invalid_argument for a speed or return mode the model does not have, or a table of
  // another channel count. The Pandar40P takes what SyntheticSensor takes (speeds 60..1500).
  AnyModelSensor(SensorModelId model, const ModelSensorConfig& config,
                 const std::optional<Calibration>& calibration = std::nullopt);

  // Writes the next datagram and returns its size. Throws std::invalid_argument when `out` is
  // shorter than it (kLargestDatagramBytes always suffices).
  std::size_t next(std::span<std::uint8_t> out);

  SensorModelId model() const noexcept { return model_; }
  std::int64_t last_packet_time_ns() const noexcept;
  std::int64_t packet_period_ns() const noexcept;
  std::uint64_t packets() const noexcept;
  // The largest datagram this sensor writes (the 40P's and the Pandar64's depend on the
  // sequence; the others are fixed).
  std::size_t max_datagram_bytes() const noexcept;

 private:
  SensorModelId model_;
  std::variant<SyntheticSensor, ModelSensor<Pandar64>, ModelSensor<PandarXT32>,
               ModelSensor<PandarXT16>, ModelSensor<PandarQT128>>
      sensor_;
};

}  // namespace pandarcap
