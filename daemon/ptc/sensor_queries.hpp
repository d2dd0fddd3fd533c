// The four questions pandarcap asks a sensor over PTC, each answered with a parsed value or one
// error (transport, return code, or a payload that does not parse; all counted by the client).
//
//   fetch_calibration  0x05  the angle-correction CSV, validated as a calibration file is
//   fetch_inventory    0x07  serial number, firmware versions
//   fetch_settings     0x08  clock source, spin rate, return mode, destination
//   fetch_status       0x09  uptime, motor speed, temperatures, GPS and PTP state
//   fetch_ptp_status   0x06  PTP offset from master, where the firmware answers it
//
// A payload longer than its layout parses; `extra_bytes` says by how much (newer firmware), and
// the caller logs it once.
#pragma once

#include <optional>

#include "core/decode/calibration.hpp"
#include "core/ptc/ptc_messages.hpp"
#include "daemon/ptc/ptc_client.hpp"

namespace pandarcap {

template <typename T>
struct Fetched {
  std::optional<T> value;
  std::optional<PtcError> error;  // exactly one of value and error is set
  std::size_t extra_bytes = 0;
};

// The table's `source` is "sensor ADDRESS:PORT".
Fetched<Calibration> fetch_calibration(
    PtcClient& client, std::optional<SensorModelId> model = SensorModelId::kPandar40P);
Fetched<ptc::SensorInventory> fetch_inventory(PtcClient& client);
Fetched<ptc::SensorSettings> fetch_settings(PtcClient& client);
Fetched<ptc::SensorStatus> fetch_status(PtcClient& client);
// 0x06 query 0x01; many sensors answer "unsupported": an error of kind kErrorCode, code 0x05,
// not counted in the client's errors (the sensor answered; it lacks the feature).
Fetched<ptc::PtpDiagnostics> fetch_ptp_status(PtcClient& client);

}  // namespace pandarcap
