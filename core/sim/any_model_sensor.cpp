// AnyModelSensor (any_model_sensor.hpp): the model's simulator in a variant.
#include "core/sim/any_model_sensor.hpp"

#include <fmt/format.h>

#include <stdexcept>
#include <type_traits>

#include "core/sensors/sensor_models.hpp"

namespace pandarcap {

SyntheticSensorConfig synthetic_sensor_config(const ModelSensorConfig& config) {
  SyntheticSensorConfig sc;
  sc.rpm = config.rpm;
  sc.return_mode = config.return_mode;
  sc.udp_sequence = config.udp_sequence;
  sc.first_sequence = config.first_sequence;
  sc.start_unix_ns = config.start_unix_ns;
  sc.start_azimuth_deg = config.start_azimuth_deg;
  sc.seed = config.seed;
  return sc;
}

ModelSensorConfig model_sensor_config(const SyntheticSensorConfig& config) {
  ModelSensorConfig m;
  m.rpm = config.rpm;
  m.return_mode = config.return_mode;
  m.udp_sequence = config.udp_sequence;
  m.first_sequence = config.first_sequence;
  m.start_unix_ns = config.start_unix_ns;
  m.start_azimuth_deg = config.start_azimuth_deg;
  m.seed = config.seed;
  return m;
}

namespace {

using Variant = std::variant<SyntheticSensor, ModelSensor<Pandar64>, ModelSensor<PandarXT32>,
                             ModelSensor<PandarXT16>, ModelSensor<PandarQT128>>;

Variant make_sensor(SensorModelId model, const ModelSensorConfig& config,
                    const std::optional<Calibration>& calibration) {
  const Calibration table = calibration ? *calibration : Calibration::nominal(model);
  return with_model(model, [&]<class M>(std::type_identity<M>) -> Variant {
    if constexpr (std::is_same_v<M, Pandar40P>) {
      if (table.channel_count != M::kChannels) {
        throw std::invalid_argument(fmt::format("a Pandar40P calibration has {} channels, not {}",
                                                M::kChannels, table.channel_count));
      }
      return Variant(std::in_place_type<SyntheticSensor>, synthetic_sensor_config(config), table);
    } else {
      return Variant(std::in_place_type<ModelSensor<M>>, config, table);
    }
  });
}

}  // namespace

AnyModelSensor::AnyModelSensor(SensorModelId model, const ModelSensorConfig& config,
                               const std::optional<Calibration>& calibration)
    : model_(model), sensor_(make_sensor(model, config, calibration)) {}

std::size_t AnyModelSensor::next(std::span<std::uint8_t> out) {
  return std::visit(
      [&](auto& sensor) -> std::size_t {
        if constexpr (std::is_same_v<std::decay_t<decltype(sensor)>, SyntheticSensor>) {
          // The 40P's writer takes a whole slot; a shorter buffer still fits a 1262-byte packet
          // only when no sequence is on, so the check is the slot's size.
          if (out.size() < kMaxPacketBytes) {
            throw std::invalid_argument(
                fmt::format("a Pandar40P datagram needs {} bytes, the buffer has {}",
                            kMaxPacketBytes, out.size()));
          }
          return sensor.next(out.first<kMaxPacketBytes>());
        } else {
          return sensor.next(out);
        }
      },
      sensor_);
}

std::int64_t AnyModelSensor::last_packet_time_ns() const noexcept {
  return std::visit([](const auto& sensor) { return sensor.last_packet_time_ns(); }, sensor_);
}

std::int64_t AnyModelSensor::packet_period_ns() const noexcept {
  return std::visit([](const auto& sensor) { return sensor.packet_period_ns(); }, sensor_);
}

std::uint64_t AnyModelSensor::packets() const noexcept {
  return std::visit([](const auto& sensor) { return sensor.packets(); }, sensor_);
}

std::size_t AnyModelSensor::max_datagram_bytes() const noexcept {
  return std::visit(
      [](const auto& sensor) -> std::size_t {
        if constexpr (std::is_same_v<std::decay_t<decltype(sensor)>, SyntheticSensor>) {
          return sensor.config().udp_sequence ? kPacketWithSequenceBytes : kPacketBytes;
        } else {
          return sensor.datagram_bytes();
        }
      },
      sensor_);
}

}  // namespace pandarcap
