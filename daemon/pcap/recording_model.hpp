// Which sensor model a recording holds, from its first packets: a replay with sensor.model =
// "auto" builds its pipeline for that model before the first packet is decoded (its calibration
// is read with the model's channel count, its arenas sized for it).
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "core/sensors/model_detection.hpp"
#include "core/sensors/sensor_model_id.hpp"

namespace pandarcap {

struct RecordingModel {
  // kKnown or kUnsupported: the first packet that named a model; or, when no packet read names
  // one, kKnown with the model the file names (from_file).
  DetectedModel detected;
  std::uint64_t records = 0;  // datagrams read to find it
  // The model the file itself names (an MCAP file pandarcapd wrote: its packets channel's
  // sensor_model), whether or not the packets agree: the packets are authoritative, a caller
  // says when the two differ.
  std::optional<SensorModelId> named;
  bool from_file = false;  // detected is the file's word: no packet read named a model
};

// Reads up to `max_datagrams` UDP datagrams of `path` (to `port` when given) for the first packet
// of a known model; else the file's own word (MCAP); else the first unsupported model's header
// seen (one look-alike datagram does not name a recording whose packets are a known model's).
// None when nothing names a model: the replay then lets its packets choose, as live does.
// Throws CaptureError when the file cannot be read as a capture.
std::optional<RecordingModel> recording_model(const std::string& path,
                                              std::optional<std::uint16_t> port,
                                              std::uint64_t max_datagrams = 20'000);

}  // namespace pandarcap
