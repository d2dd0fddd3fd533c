// The simulated sensor of `pandarcapd --simulate`: a thread that sends the core generator's
// packets of the chosen model (core/sim/any_model_sensor.hpp) over loopback UDP to the daemon's
// own socket at the model's real rate (a Pandar40P's 1800 packets/s single return, 3600 dual; a
// QT128's 9000 dual), so the whole live path runs with no hardware.
// Packets due are sent together with sendmmsg every millisecond. The room is rendered with the
// simulated unit's own angles (core/sim/simulated_unit.hpp), the table its PTC serves.
#pragma once

#include <atomic>
#include <cstdint>
#include <string>

#include "core/sensors/sensor_model_id.hpp"
#include "core/sim/any_model_sensor.hpp"
#include "core/sim/synthetic_sensor.hpp"

namespace pandarcap {

class SimulatedSender {
 public:
  // Throws std::system_error when the socket cannot be created or bound to `source_ip`.
  // Throws std::invalid_argument for a speed or return mode `model` does not have.
  SimulatedSender(SensorModelId model, const SyntheticSensorConfig& config,
                  const std::string& source_ip, const std::string& destination_ip,
                  std::uint16_t destination_port);
  ~SimulatedSender();
  SimulatedSender(const SimulatedSender&) = delete;
  SimulatedSender& operator=(const SimulatedSender&) = delete;

  // Sends until `stop` is set.
  void run(const std::atomic<bool>& stop);
  std::uint64_t packets_sent() const noexcept { return sent_.load(std::memory_order_relaxed); }
  std::uint64_t send_errors() const noexcept { return errors_.load(std::memory_order_relaxed); }

 private:
  AnyModelSensor sensor_;
  int fd_ = -1;
  std::atomic<std::uint64_t> sent_{0};
  std::atomic<std::uint64_t> errors_{0};
};

}  // namespace pandarcap
