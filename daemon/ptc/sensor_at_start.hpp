// What the daemon learns from the sensor before it captures: the calibration to decode with,
// chosen by sensor.calibration_source, and the sensor's identity and configuration.
//
//   auto     the sensor's own table if it answers over PTC within ptc_timeout_ms, else
//            calibration_file if given, else the nominal table (each fallback logged); a
//            calibration_file given is checked first either way
//   sensor   the sensor's own table; no answer stops the start (SensorUnavailable)
//   file     calibration_file
//   nominal  the Pandar40P design table
//
// When the sensor is asked (`ptc` given) and gives its table, its inventory (serial, firmware)
// and configuration (clock source, spin rate) are read too; a failure there is logged, never
// fatal. Without `ptc` (a replay, no sensor_ip) "auto" goes straight to the file or nominal.
#pragma once

#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>

#include "core/decode/calibration.hpp"
#include "core/ptc/ptc_messages.hpp"
#include "daemon/ptc/ptc_client.hpp"

namespace pandarcap {

// calibration_source = "sensor" and the sensor did not give its table.
class SensorUnavailable : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct SensorAtStart {
  Calibration calibration;
  // "sensor", "file", "nominal", or "recording" (a replay: the table the recording carries)
  std::string calibration_source;
  std::string endpoint;  // "ADDRESS:PORT" when the sensor was asked
  std::optional<ptc::SensorInventory> inventory;
  std::optional<ptc::SensorSettings> settings;
  std::uint64_t ptc_requests = 0, ptc_errors = 0;
  // The sensor's model when known at start (a fixed sensor.model, a replay's packets, the
  // simulated sensor's: RunSource::model); none for a live "auto", whose packets name it later.
  std::optional<SensorModelId> model;

  // One line for the log: "from sensor (serial PCSIM40P00000001, firmware sim-fw-1.0) at
  // 127.0.0.1:41234", "from file /etc/pandarcap/front.csv", "nominal Pandar40P table".
  std::string describe() const;
  // The neighbour file of recordings (raw/sensor.json): model (its display name, null when not
  // known at start), source, identity, configuration.
  // `device_name` and `config_hash` (daemon_options.hpp) say which machine and configuration
  // made the recordings beside it.
  std::string to_json(const std::string& device_name, const std::string& config_hash) const;
};

// Throws CalibrationError for a calibration file that is missing or invalid, SensorUnavailable
// when the source is "sensor" and it does not answer with a valid table.
// `model`: the sensor's, when known (a fixed sensor.model, a replay's packets); none: live
// "auto", where a table of any supported model's channel count is taken.
SensorAtStart resolve_sensor_at_start(
    const std::string& calibration_source, const std::string& calibration_file,
    const std::optional<PtcClientOptions>& ptc,
    std::optional<SensorModelId> model = SensorModelId::kPandar40P);

}  // namespace pandarcap
