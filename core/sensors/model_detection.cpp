#include "core/sensors/model_detection.hpp"

#include <cstddef>
#include <type_traits>

#include "core/sensors/sensor_models.hpp"

namespace pandarcap {

namespace {

DetectedModel known(SensorModelId id) noexcept {
  return {DetectionKind::kKnown, id, {}, RejectReason::kNone};
}
DetectedModel unsupported(std::string_view name) noexcept {
  return {DetectionKind::kUnsupported, SensorModelId::kPandar40P, name, RejectReason::kNone};
}

// What Hesai's SDK tells apart by length alone (udp_parser.cc, CreatGeneralParser).
std::optional<DetectedModel> by_length(std::span<const std::uint8_t> p) noexcept {
  const std::size_t n = p.size();
  if ((n == kPacketBytes || n == kPacketWithSequenceBytes) && p[0] == kMarker0 &&
      p[1] == kMarker1) {
    return known(SensorModelId::kPandar40P);
  }
  if (n < 4 || p[0] != 0xEE || p[1] != 0xFF) return std::nullopt;
  if ((n == Pandar64::kDatagramBytes[0] || n == Pandar64::kDatagramBytes[1]) &&
      p[Pandar64::kLaserCountOffset] == Pandar64::kChannels &&
      p[Pandar64::kBlockCountOffset] == Pandar64::kBlocks) {
    return known(SensorModelId::kPandar64);
  }
  // The Pandar20's lengths as the SDK has them (no capture was seen; not decoded).
  if (n == 1388 || n == 1392) return unsupported("Pandar20");
  return std::nullopt;
}

}  // namespace

DetectedModel identify_model(std::span<const std::uint8_t> p) noexcept {
  if (p.size() < 2) return {};
  if (const auto model = by_length(p)) return *model;
  // The pre-header: EE FF, major, minor, two reserved bytes, laser count, block count.
  if (p.size() < 8 || p[0] != 0xEE || p[1] != 0xFF) return {};
  const std::uint8_t major = p[2], minor = p[3], lasers = p[6], blocks = p[7];
  switch ((major << 8) | minor) {
    case 0x0601:
      if (lasers == 32 && blocks == 8) return known(SensorModelId::kPandarXT32);
      if (lasers == 16 && blocks == 8) return known(SensorModelId::kPandarXT16);
      if (lasers == 32 && blocks == 6) return unsupported("XT32M");
      return {};
    case 0x0302:
      if (lasers == 128 && blocks == 2) return known(SensorModelId::kPandarQT128);
      return {};
    case 0x0301:
      return unsupported("QT64");
    case 0x0401:
    case 0x0403:
      return unsupported("AT128");
    case 0x0104:
      return unsupported("OT128/Pandar128E3X/E4X");
    case 0x0108:
      return unsupported("JT16");
    case 0x0702:
      return unsupported("FT120");
    default:
      return {};
  }
}

DetectedModel detect_model(std::span<const std::uint8_t> p) noexcept {
  DetectedModel found = identify_model(p);
  if (found.kind != DetectionKind::kKnown) return found;
  found.reject =
      with_model(found.model, [&]<class M>(std::type_identity<M>) { return M::validate(p); });
  if (found.reject != RejectReason::kNone) found.kind = DetectionKind::kUnknown;
  return found;
}

}  // namespace pandarcap
