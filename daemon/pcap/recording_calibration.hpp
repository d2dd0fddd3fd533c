// The calibration a recording carries, for a replay or pandarcap-inspect given no --calibration:
//   - a pcap or pcap.zst: the sidecar beside it, STEM.calibration.csv (recording_sidecars.hpp),
//     which pandarcapd writes when it finishes the recording; a NAME.pcap[.zst].part a killed
//     run left (no sidecar yet): the calibration.csv of its directory, its run's;
//   - an MCAP file: its calibration.csv attachment (every file pandarcapd writes has one).
// The kind is told by the file's first bytes (the MCAP magic), as CaptureReader tells it.
//
// Found and valid: the table, its `source` naming where it came from ("raw/x.calibration.csv",
// "mcap/x.mcap (attachment calibration.csv)"). None there: nothing, and `looked_for` says where
// it looked (the caller then uses the nominal table and says so). There but not usable (a table
// for another model's channel count, not a CSV, an attachment that fails its CRC): a
// CalibrationError naming it, never a silent fall back to the nominal table, whose angles would
// put every point in the wrong place.
#pragma once

#include <optional>
#include <string>

#include "core/decode/calibration.hpp"

namespace pandarcap {

// Throws CalibrationError as said above.
// `model`: the table must have its channels (none: any supported model's count).
std::optional<Calibration> recording_calibration(
    const std::string& recording_path, std::string& looked_for,
    std::optional<SensorModelId> model = SensorModelId::kPandar40P);

}  // namespace pandarcap
