#include "core/sensors/sensor_model_id.hpp"

#include <cstddef>

namespace pandarcap {

namespace {

char lower(char c) noexcept {
  return c >= 'A' && c <= 'Z' ? static_cast<char>(c - 'A' + 'a') : c;
}

}  // namespace

std::string_view display_name(SensorModelId id) noexcept {
  switch (id) {
    case SensorModelId::kPandar40P:
      return "Pandar40P";
    case SensorModelId::kPandar64:
      return "Pandar64";
    case SensorModelId::kPandarXT32:
      return "PandarXT32";
    case SensorModelId::kPandarXT16:
      return "PandarXT16";
    case SensorModelId::kPandarQT128:
      return "PandarQT128";
  }
  return "unknown";
}

std::string_view lower_case_name(SensorModelId id) noexcept {
  switch (id) {
    case SensorModelId::kPandar40P:
      return "pandar40p";
    case SensorModelId::kPandar64:
      return "pandar64";
    case SensorModelId::kPandarXT32:
      return "pandarxt32";
    case SensorModelId::kPandarXT16:
      return "pandarxt16";
    case SensorModelId::kPandarQT128:
      return "pandarqt128";
  }
  return "unknown";
}

std::optional<SensorModelId> parse_sensor_model(std::string_view name) noexcept {
  for (SensorModelId id : kSensorModelIds) {
    const std::string_view lower_name = lower_case_name(id);
    if (name.size() != lower_name.size()) continue;
    bool same = true;
    for (std::size_t i = 0; same && i < name.size(); ++i)
      same = lower(name[i]) == lower_name[i];
    if (same) return id;
  }
  return std::nullopt;
}

}  // namespace pandarcap
