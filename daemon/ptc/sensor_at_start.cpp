#include "daemon/ptc/sensor_at_start.hpp"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <nlohmann/json.hpp>

#include "daemon/io/calibration_file.hpp"
#include "daemon/ptc/sensor_json.hpp"
#include "daemon/ptc/sensor_queries.hpp"

namespace pandarcap {
std::string SensorAtStart::describe() const {
  if (calibration_source == "sensor") {
    return fmt::format("from sensor (serial {}, firmware {}) at {}",
                       inventory ? inventory->serial : "unknown",
                       inventory ? inventory->sensor_firmware : "unknown", endpoint);
  }
  if (calibration_source == "file") return "from file " + calibration.source;
  if (calibration_source == "recording") return "from the recording: " + calibration.source;
  return fmt::format("nominal {} table", display_name(calibration.model()));
}

std::string SensorAtStart::to_json(const std::string& device_name,
                                   const std::string& config_hash) const {
  nlohmann::ordered_json j;
  j["device_name"] = device_name;
  j["config_hash"] = config_hash;
  j["model"] = model ? nlohmann::ordered_json(display_name(*model)) : nlohmann::ordered_json();
  j["calibration_source"] = calibration_source;
  j["calibration"] = calibration.source;
  j["ptc_endpoint"] =
      endpoint.empty() ? nlohmann::ordered_json() : nlohmann::ordered_json(endpoint);
  j["inventory"] = inventory ? pandarcap::to_json(*inventory) : nlohmann::ordered_json();
  j["config"] = settings ? pandarcap::to_json(*settings) : nlohmann::ordered_json();
  return j.dump(2) + "\n";
}

SensorAtStart resolve_sensor_at_start(const std::string& source, const std::string& file,
                                      const std::optional<PtcClientOptions>& ptc,
                                      std::optional<SensorModelId> model) {
  const SensorModelId nominal_model = model.value_or(SensorModelId::kPandar40P);
  SensorAtStart out;
  if (source == "nominal") {
    out.calibration = Calibration::nominal(nominal_model);
    out.calibration_source = "nominal";
    return out;
  }
  if (source == "file") {
    out.calibration = load_calibration(file, model);
    out.calibration_source = "file";
    return out;
  }
  if (!ptc && source == "sensor") {
    throw SensorUnavailable(
        "calibration_source = \"sensor\" needs sensor.sensor_ip (where PTC connects)");
  }

  // A calibration_file named beside "auto" is checked now, whatever the sensor answers: a broken
  // fallback is a configuration error to hear about today, not on the day the sensor is silent.
  std::optional<Calibration> file_table;
  if (!file.empty()) file_table = load_calibration(file, model);
  const auto fall_back = [&] {
    out.calibration_source = file_table ? "file" : "nominal";
    out.calibration = file_table ? std::move(*file_table) : Calibration::nominal(nominal_model);
  };
  if (!ptc) {
    fall_back();
    return out;
  }

  PtcClient client(*ptc);
  out.endpoint = client.endpoint();
  Fetched<Calibration> table = fetch_calibration(client, model);
  if (table.value) {
    out.calibration = std::move(*table.value);
    out.calibration_source = "sensor";
    // Who it is and how it is set up: logged, reported, saved; never a reason to stop.
    Fetched<ptc::SensorInventory> inventory = fetch_inventory(client);
    if (inventory.value) {
      out.inventory = std::move(inventory.value);
    } else {
      spdlog::warn("sensor inventory: {}", inventory.error->message);
    }
    Fetched<ptc::SensorSettings> settings = fetch_settings(client);
    if (settings.value) {
      out.settings = settings.value;
    } else {
      spdlog::warn("sensor config: {}", settings.error->message);
    }
  } else if (source == "sensor") {
    throw SensorUnavailable(
        fmt::format("calibration_source = \"sensor\": {}", table.error->message));
  } else {
    fall_back();
    spdlog::warn("calibration: {}; using {}", table.error->message,
                 file.empty() ? "the nominal table" : "calibration_file " + file);
  }
  out.ptc_requests = client.requests();
  out.ptc_errors = client.errors();
  return out;
}

}  // namespace pandarcap
