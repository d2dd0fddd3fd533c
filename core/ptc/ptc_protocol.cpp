#include "core/ptc/ptc_protocol.hpp"

#include <fmt/format.h>

namespace pandarcap::ptc {

std::string_view to_string(Command command) noexcept {
  switch (command) {
    case Command::kGetCalibration:
      return "calibration";
    case Command::kPtpDiagnostics:
      return "ptp_diagnostics";
    case Command::kGetInventory:
      return "inventory";
    case Command::kGetConfig:
      return "config";
    case Command::kGetStatus:
      return "status";
  }
  return "unknown command";
}

std::string_view describe_return_code(std::uint8_t code) noexcept {
  static constexpr std::string_view kCodes[] = {
      "no error",      "invalid input parameter", "server connection failed",  "invalid data",
      "out of memory", "unsupported command",     "FPGA communication failed", "other error"};
  return code < std::size(kCodes) ? kCodes[code] : "unknown return code";
}

std::string_view to_string(ErrorKind kind) noexcept {
  switch (kind) {
    case ErrorKind::kConnectFailed:
      return "connect_failed";
    case ErrorKind::kTimeout:
      return "timeout";
    case ErrorKind::kIncomplete:
      return "incomplete";
    case ErrorKind::kBadMagic:
      return "bad_magic";
    case ErrorKind::kUnrelatedResponse:
      return "unrelated_response";
    case ErrorKind::kOversize:
      return "oversize";
    case ErrorKind::kErrorCode:
      return "error_code";
    case ErrorKind::kUnexpectedPayload:
      return "unexpected_payload";
  }
  return "unknown";
}

std::array<std::uint8_t, kHeaderBytes> encode_header(Command command, std::uint8_t return_code,
                                                     std::uint32_t payload_length) noexcept {
  return {kMagic[0],
          kMagic[1],
          static_cast<std::uint8_t>(command),
          return_code,
          static_cast<std::uint8_t>(payload_length >> 24),
          static_cast<std::uint8_t>(payload_length >> 16),
          static_cast<std::uint8_t>(payload_length >> 8),
          static_cast<std::uint8_t>(payload_length)};
}

ResponseHeader decode_header(std::span<const std::uint8_t, kHeaderBytes> b) noexcept {
  return ResponseHeader{.command = b[2],
                        .return_code = b[3],
                        .payload_length = (std::uint32_t{b[4]} << 24) |
                                          (std::uint32_t{b[5]} << 16) | (std::uint32_t{b[6]} << 8) |
                                          std::uint32_t{b[7]}};
}

std::optional<HeaderProblem> check_response_header(const ResponseHeader& header,
                                                   std::span<const std::uint8_t, kHeaderBytes> b,
                                                   Command expected,
                                                   std::uint32_t max_payload_bytes) {
  if (b[0] != kMagic[0] || b[1] != kMagic[1]) {
    return HeaderProblem{ErrorKind::kBadMagic,
                         fmt::format("wrong magic bytes {:02X} {:02X} (expected 47 74): not a PTC "
                                     "server",
                                     b[0], b[1])};
  }
  if (header.command != static_cast<std::uint8_t>(expected)) {
    return HeaderProblem{ErrorKind::kUnrelatedResponse,
                         fmt::format("response to command 0x{:02X}, not to the request's 0x{:02X}",
                                     header.command, static_cast<unsigned>(expected))};
  }
  if (header.payload_length > max_payload_bytes) {
    return HeaderProblem{ErrorKind::kOversize,
                         fmt::format("announces a {}-byte payload, more than the {} accepted",
                                     header.payload_length, max_payload_bytes)};
  }
  return std::nullopt;
}

}  // namespace pandarcap::ptc
