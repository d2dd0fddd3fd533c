// The simulated Pandar40P as one particular unit: what its control protocol (PTC) answers.
//
// Like a real unit it has its own angle calibration, which differs from the nominal design
// table: each channel's elevation by -0.40..+0.40° and its azimuth offset by -0.20..+0.20°,
// fixed per channel (a deterministic pattern, not random), so that decoding with the nominal
// table puts points measurably off the room's surfaces and decoding with the fetched table puts
// them on. `pandarcapd --simulate` renders its packets with this table and serves it over PTC.
#pragma once

#include <cstdint>

#include "core/decode/calibration.hpp"
#include "core/ptc/ptc_messages.hpp"

namespace pandarcap {

struct SimulatedUnit {
  Calibration calibration;  // this unit's table (source "simulated unit")
  ptc::SensorInventory inventory;
  ptc::SensorSettings settings;  // clock source PTP, spin rate and modes as simulated
  std::uint8_t ptp_state = static_cast<std::uint8_t>(ptc::PtpState::kLocked);
  // Whether it answers PTP diagnostics (0x06), and the offset it reports. Off by default: as
  // far as is known a Pandar40P answers "unsupported".
  bool answers_ptp_diagnostics = false;
  std::int64_t ptp_offset_ns = 0;

  // The unit's status `uptime_s` seconds after power-on.
  ptc::SensorStatus status(std::uint32_t uptime_s) const;
};

// The table of a simulated unit of `model`: its nominal table moved by the pattern above (the
// same per channel index for every model), kept to three decimals. The Pandar40P's is
// SimulatedUnit::calibration; the other models' simulators (model_sensor.hpp) render with theirs
// where a run is to decode with a table fetched or loaded rather than the nominal one.
Calibration simulated_unit_calibration(SensorModelId model);

// The simulated unit, spinning at `rpm`, sending `return_mode_code` (the packets' tail code)
// with or without a UDP sequence, to `data_port`.
// `model`: whose table and laser count its PTC answers.
SimulatedUnit simulated_unit(int rpm = 600, std::uint8_t return_mode_code = 0x39,
                             bool udp_sequence = false, std::uint16_t data_port = 2368,
                             SensorModelId model = SensorModelId::kPandar40P);

}  // namespace pandarcap
