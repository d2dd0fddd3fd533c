#include "core/sensors/packet.hpp"

namespace pandarcap {

std::string_view to_string(ReturnMode mode) noexcept {
  switch (mode) {
    case ReturnMode::kStrongest:
      return "strongest";
    case ReturnMode::kLast:
      return "last";
    case ReturnMode::kDual:
      return "dual";
  }
  return "unknown";
}

std::optional<ReturnMode> return_mode_from_byte(std::uint8_t value) noexcept {
  switch (value) {
    case 0x37:
    case 0x38:
    case 0x39:
      return static_cast<ReturnMode>(value);
    default:
      return std::nullopt;
  }
}

std::optional<ReturnMode> return_mode_from_string(std::string_view name) noexcept {
  for (ReturnMode mode : {ReturnMode::kStrongest, ReturnMode::kLast, ReturnMode::kDual}) {
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
  if (!return_mode_from_byte(p[kBodyBytes + 14])) return RejectReason::kBadReturnMode;
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
