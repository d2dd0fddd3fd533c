// pandarcap-inspect's per-packet dump: a packet's fields as its model reads them, as a JSON
// object (--json) and as one line of the table (the default).
//
// Every model: index, record time, addresses, size, status; for an accepted packet the first and
// last block's azimuth, motor speed, µs, return mode, factory byte, date and time (the year by
// the model's rule), UDP sequence (null when the packet has none) and the high-temperature flag.
// The Pandar40P adds its tail's status_id / status_value (its fields and columns are those of
// the 40P-only tool before, unchanged); the PandarQT128 adds its tail's mode flag (which firing
// sequence the packet holds) and its functional-safety block's lidar state and counter (null
// without the block).
#pragma once

#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>

#include "core/sensors/packet.hpp"
#include "core/sensors/sensor_model_id.hpp"
#include "daemon/pcap/capture_reader.hpp"

namespace pandarcap {

// `reason`: what the decoder said of the packet; fields only when kNone (a rejected payload's
// bytes mean nothing).
nlohmann::json packet_json(SensorModelId model, std::uint64_t index, const CaptureRecord& record,
                           RejectReason reason, bool has_endpoints);
// The table's heading and one packet's line (from packet_json's object).
std::string packet_heading(SensorModelId model);
std::string packet_line(SensorModelId model, const nlohmann::json& packet);

}  // namespace pandarcap
