// Which model sent a payload, from the payload alone (hesai-models.md §1, Hesai's SDK's rule):
//
//   1. by length first: 1262 / 1266 bytes starting FF EE is a Pandar40P; 1194 / 1198 bytes
//      starting EE FF 40 06 a Pandar64 (its bytes 2-3 are laser and block count, never a
//      protocol version: read as one they would say 64.6); 1388 / 1392 bytes starting EE FF a
//      Pandar20 (not supported);
//   2. else by the pre-header EE FF, major, minor (bytes 2, 3) and laser / block count (6, 7):
//        6.1   32 lasers 8 blocks PandarXT32, 16 lasers 8 blocks PandarXT16, 32 lasers
//              6 blocks XT32M (not supported)
//        3.2   128 lasers 2 blocks PandarQT128;   3.1 QT64 (not supported)
//        4.1, 4.3 AT128;  1.4 OT128/Pandar128E3X/E4X;  1.8 JT16;  7.2 FT120 (not supported)
//   3. else unknown.
//
// identify_model() is that and only that: the length and the first 8 bytes, no loop, cheap
// enough for a receive thread. detect_model() then asks the identified model's validate() as
// well: a known model is reported only for a payload that model accepts.
#pragma once

#include <cstdint>
#include <span>
#include <string_view>

#include "core/sensors/packet.hpp"
#include "core/sensors/sensor_model_id.hpp"

namespace pandarcap {

enum class DetectionKind : std::uint8_t {
  kKnown,        // a supported model: `model`
  kUnsupported,  // a Hesai model pandarcap does not decode: `unsupported_name`
  kUnknown,      // not a Hesai point-cloud packet pandarcap recognises
};

struct DetectedModel {
  DetectionKind kind = DetectionKind::kUnknown;
  SensorModelId model = SensorModelId::kPandar40P;  // when kKnown
  // When kUnsupported: "AT128", "OT128/Pandar128E3X/E4X", "JT16", "FT120", "QT64", "XT32M",
  // "Pandar20" (static text).
  std::string_view unsupported_name;
  // detect_model() only: kUnknown because the identified model's validate() said this
  // (`model` is the identified one); kNone otherwise.
  RejectReason reject = RejectReason::kNone;
};

// Length and first bytes only; reads nothing past payload.size().
DetectedModel identify_model(std::span<const std::uint8_t> payload) noexcept;
// identify_model(), then the identified model's validate().
DetectedModel detect_model(std::span<const std::uint8_t> payload) noexcept;

}  // namespace pandarcap
