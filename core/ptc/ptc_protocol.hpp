// PTC framing (../shared/spec/pandar40p-ptc.md §2-3): every message is an 8-byte header and a
// payload; integers are big-endian.
//
//   request   47 74 CMD 00 LEN LEN LEN LEN  payload     ("get calibration": 47 74 05 00 00 00 00
//   00) response  47 74 CMD RC  LEN LEN LEN LEN  payload     (RC = return code, 0 = no error)
//
// A response must echo the request's command; one that does not is unrelated and the connection
// is not to be trusted further. The payload length is checked against the caller's bound before
// any payload is read, so a length of 2^32-1 costs nothing. Pure: no sockets here.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>

namespace pandarcap::ptc {

inline constexpr std::uint16_t kDefaultPort = 9347;
inline constexpr std::size_t kHeaderBytes = 8;
inline constexpr std::uint8_t kMagic[2] = {0x47, 0x74};  // "Gt"

// The read-only commands a capture daemon sends (spec §4). Commands that change the sensor
// (§5) are deliberately absent.
enum class Command : std::uint8_t {
  kGetCalibration = 0x05,
  kPtpDiagnostics = 0x06,
  kGetInventory = 0x07,
  kGetConfig = 0x08,
  kGetStatus = 0x09,
};
std::string_view to_string(Command command) noexcept;  // "calibration", "inventory", ...

// The sensor's return codes (byte 3 of a response).
inline constexpr std::uint8_t kReturnOk = 0x00;
inline constexpr std::uint8_t kReturnUnsupported = 0x05;
// "invalid input parameter", ..., "other error"; "unknown return code" past 0x07.
std::string_view describe_return_code(std::uint8_t code) noexcept;

// What went wrong with one request, client-side failures kept apart from the sensor's own
// return codes (as nebula does). Each has a counter and a message naming it.
enum class ErrorKind : std::uint8_t {
  kConnectFailed,      // refused, unreachable, no route
  kTimeout,            // connect, or the whole response, past its deadline
  kIncomplete,         // the connection ended before the header or payload was complete
  kBadMagic,           // the response does not start with 47 74
  kUnrelatedResponse,  // the response's command byte is not the request's
  kOversize,           // the announced payload is longer than the client accepts
  kErrorCode,          // the sensor answered with a non-zero return code
  kUnexpectedPayload,  // the payload does not parse (too short, not a calibration table)
};
inline constexpr std::size_t kErrorKindCount = 8;
std::string_view to_string(ErrorKind kind) noexcept;  // "connect_failed", "timeout", ...

std::array<std::uint8_t, kHeaderBytes> encode_header(Command command, std::uint8_t return_code,
                                                     std::uint32_t payload_length) noexcept;
// A request's header: return-code byte 0.
inline std::array<std::uint8_t, kHeaderBytes> request_header(
    Command command, std::uint32_t payload_length) noexcept {
  return encode_header(command, 0, payload_length);
}

struct ResponseHeader {
  std::uint8_t command = 0;
  std::uint8_t return_code = 0;
  std::uint32_t payload_length = 0;
};

// The header's fields, whatever they say.
ResponseHeader decode_header(std::span<const std::uint8_t, kHeaderBytes> bytes) noexcept;

struct HeaderProblem {
  ErrorKind kind;
  std::string message;  // "wrong magic bytes 48 54 (expected 47 74)"
};
// Checks a response header against the request's command and the largest payload accepted.
// A non-zero return code is not a problem here: it may come with a payload worth reading
// (a message), and the caller reports it after reading that payload.
std::optional<HeaderProblem> check_response_header(
    const ResponseHeader& header, std::span<const std::uint8_t, kHeaderBytes> bytes,
    Command expected, std::uint32_t max_payload_bytes);

}  // namespace pandarcap::ptc
