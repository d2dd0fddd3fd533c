// Which sensor model: the identity every part of pandarcap names a model by.
//
//   SensorModelId       display name   lower-case name (health JSON "sensor", sensor.json, logs)
//   kPandar40P          Pandar40P      pandar40p
//   kPandar64           Pandar64       pandar64
//   kPandarXT32         PandarXT32     pandarxt32
//   kPandarXT16         PandarXT16     pandarxt16
//   kPandarQT128        PandarQT128    pandarqt128
//
// The facts of each model are in its own header (pandar40p.hpp, pandar64.hpp, pandar_xt.hpp,
// pandar_qt128.hpp); sensor_models.hpp holds them all and turns an id into its model's type once.
// Configuration's "auto" is not a model: the caller handles it before parse_sensor_model().
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string_view>

namespace pandarcap {

enum class SensorModelId : std::uint8_t {
  kPandar40P,
  kPandar64,
  kPandarXT32,
  kPandarXT16,
  kPandarQT128,
};
inline constexpr std::array<SensorModelId, 5> kSensorModelIds = {
    SensorModelId::kPandar40P, SensorModelId::kPandar64, SensorModelId::kPandarXT32,
    SensorModelId::kPandarXT16, SensorModelId::kPandarQT128};

// The most channels any supported model has (the PandarQT128's): the calibration's and the
// decoders' per-channel tables are this long. Each model header asserts its count fits.
inline constexpr int kMaxChannels = 128;

// "Pandar40P", "Pandar64", "PandarXT32", "PandarXT16", "PandarQT128".
std::string_view display_name(SensorModelId id) noexcept;
// "pandar40p", "pandar64", "pandarxt32", "pandarxt16", "pandarqt128".
std::string_view lower_case_name(SensorModelId id) noexcept;
// Either name in any case ("PandarXT32", "pandarxt32", "PANDARXT32"); nullopt for anything else,
// "auto" included.
std::optional<SensorModelId> parse_sensor_model(std::string_view name) noexcept;

}  // namespace pandarcap
