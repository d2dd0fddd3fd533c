#include "core/sensors/packet.hpp"

namespace pandarcap {

std::string_view to_string(ReturnMode mode) noexcept {
  switch (mode) {
    case ReturnMode::kFirst:
      return "first";
    case ReturnMode::kSecond:
      return "second";
    case ReturnMode::kStrongest:
      return "strongest";
    case ReturnMode::kLast:
      return "last";
    case ReturnMode::kDual:
      return "dual";
    case ReturnMode::kFirstSecond:
      return "first_second";
    case ReturnMode::kFirstLast:
      return "first_last";
    case ReturnMode::kFirstStrongest:
      return "first_strongest";
    case ReturnMode::kFirstLastStrongest:
      return "first_last_strongest";
    case ReturnMode::kStrongestSecond:
      return "strongest_second";
  }
  return "unknown";
}

std::optional<ReturnMode> return_mode_from_byte(std::uint8_t value) noexcept {
  for (ReturnMode mode : kAllReturnModes) {
    if (static_cast<std::uint8_t>(mode) == value) return mode;
  }
  return std::nullopt;
}

std::optional<ReturnMode> return_mode_from_string(std::string_view name) noexcept {
  for (ReturnMode mode : kAllReturnModes) {
    if (name == to_string(mode)) return mode;
  }
  return std::nullopt;
}

std::string_view to_string(RejectReason reason) noexcept {
  switch (reason) {
    case RejectReason::kNone:
      return "none";
    case RejectReason::kBadLength:
      return "bad_length";
    case RejectReason::kBadMarker:
      return "bad_marker";
    case RejectReason::kBadAzimuth:
      return "bad_azimuth";
    case RejectReason::kBadReturnMode:
      return "bad_return_mode";
    case RejectReason::kBadCrc:
      return "bad_crc";
    case RejectReason::kWrongModel:
      return "wrong_model";
    case RejectReason::kUnsupportedModel:
      return "unsupported_model";
  }
  return "unknown";
}

RejectReason validate(std::span<const std::uint8_t> payload) noexcept {
  // Length first: every later read is inside the 1262 bytes this guarantees.
  if (payload.size() != kPacketBytes && payload.size() != kPacketWithSequenceBytes) {
    return RejectReason::kBadLength;
  }
  const std::uint8_t* p = payload.data();
  for (int b = 0; b < kBlocks; ++b) {
    const std::uint8_t* block = p + kBlockBytes * b;
    if (block[0] != kMarker0 || block[1] != kMarker1) return RejectReason::kBadMarker;
  }
  for (int b = 0; b < kBlocks; ++b) {
    if (load_u16_le(p + kBlockBytes * b + 2) >= kAzimuthLimitCdeg) return RejectReason::kBadAzimuth;
  }
  const auto mode = return_mode_from_byte(p[kBodyBytes + 14]);
  if (!mode || !mode_listed(kPandar40PReturnModes, *mode)) return RejectReason::kBadReturnMode;
  return RejectReason::kNone;
}

Tail PacketView::tail() const noexcept {
  const std::uint8_t* t = tail_bytes();
  Tail tail;
  tail.status_value = load_u16_le(t + 0);
  tail.status_id = t[2];
  tail.reserved_opaque[0] = t[3];
  tail.reserved_opaque[1] = t[4];
  tail.high_temperature = t[5] != 0;
  tail.error_code = load_u16_le(t + 6);
  tail.motor_rpm = load_u16_le(t + 8);
  tail.timestamp_us = load_u32_le(t + 10);
  tail.return_mode_byte = t[14];
  tail.factory = t[15];
  tail.utc = utc();
  tail.sequence = sequence();
  return tail;
}

}  // namespace pandarcap
