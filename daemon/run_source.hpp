// Which source a run reads (the live socket, the simulated sensor, a capture file) and what
// only the command line says about it: pandarcapd's options set it, daemon_options.hpp turns it
// into each part's options, and the start opens the source it names.
#pragma once

#include <optional>
#include <string>

#include "core/sensors/packet.hpp"
#include "core/sensors/sensor_model_id.hpp"

namespace pandarcap {

// Where the packets come from, and what only the command line says about it.
struct RunSource {
  enum class Kind { kLive, kSimulated, kReplay };
  Kind kind = Kind::kLive;
  std::string replay_path;     // kReplay
  std::optional<double> rate;  // kReplay: times real time; empty = top speed
  // --port was given: a replay keeps only datagrams to that port; the simulator sends to it
  // (else to a free port the daemon's socket picked).
  bool port_given = false;
  // --ptc-port was given: the simulated sensor's PTC is asked there instead of the built-in
  // server's free port (tests point it at a misbehaving server).
  bool ptc_port_given = false;
  // kSimulated: the sensor the simulator plays.
  int simulated_rpm = 600;
  ReturnMode simulated_mode = ReturnMode::kDual;
  bool simulated_udp_sequence = false;
  // The sensor model, once the start has chosen it (choose_sensor_model, startup_steps.hpp):
  // a fixed sensor.model, the one a replay's packets name, the simulated sensor's; none for a
  // live "auto", where the packets choose it (detect_model).
  std::optional<SensorModelId> model;
  bool detect_model = false;
  // The model --simulate plays (--sensor-model; the Pandar40P by default).
  SensorModelId simulated_model = SensorModelId::kPandar40P;
};

}  // namespace pandarcap
