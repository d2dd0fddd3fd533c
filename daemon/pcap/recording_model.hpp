// Which sensor model a recording holds, from its first packets: a replay with sensor.model =
// "auto" builds its pipeline for that model before the first packet is decoded (its calibration
// is read with the model's channel count, its arenas sized for it).
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "core/sensors/model_detection.hpp"

namespace pandarcap {

struct RecordingModel {
  DetectedModel detected;     // kKnown or kUnsupported: the first packet that named a model
  std::uint64_t records = 0;  // datagrams read to find it
};

// Reads up to `max_datagrams` UDP datagrams of `path` (to `port` when given). None when no
// datagram names a model (not a Hesai recording, or an empty one: the replay says what it
// holds). Throws CaptureError when the file cannot be read as a capture.
std::optional<RecordingModel> recording_model(const std::string& path,
                                              std::optional<std::uint16_t> port,
                                              std::uint64_t max_datagrams = 20'000);

}  // namespace pandarcap
