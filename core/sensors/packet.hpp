// Pandar40P UDP payload: layout, validation and zero-copy field access.
//
// The payload has no header. It is 10 blocks of 124 bytes, then a 22-byte tail, then (only when the
// sensor's "UDP sequence" option is on) a 4-byte sequence number:
//
//   offset 124*b      u8[2]  block marker, bytes FF EE on the wire (read as LE u16: 0xEEFF)
//   offset 124*b + 2  u16    block azimuth, 0.01 deg, 0..35999       e.g. 0x0C9B = 3227 = 32.27 deg
//   offset 124*b + 4 + 3*c   u16 distance of channel c, 4 mm/LSB, 0 = no return
//   offset 124*b + 6 + 3*c   u8  reflectivity of channel c
//   offset 1240       tail (see Tail below), offset 1262 u32 sequence (1266-byte packets only)
//
// All fields are little-endian. Reference: ../shared/spec/pandar40p-protocol.md §1.
//
// Validation never reads past the buffer it is given: the length is checked first, and every
// accessor of PacketView is only valid on a payload that validate() accepted.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <optional>
#include <span>
#include <string_view>

namespace pandarcap {

inline constexpr int kChannels = 40;
inline constexpr int kBlocks = 10;
inline constexpr std::size_t kBlockBytes = 4 + 3 * kChannels;         // 124
inline constexpr std::size_t kBodyBytes = kBlocks * kBlockBytes;      // 1240
inline constexpr std::size_t kTailBytes = 22;                         // "Additional Information"
inline constexpr std::size_t kPacketBytes = kBodyBytes + kTailBytes;  // 1262
inline constexpr std::size_t kSequenceBytes = 4;                      // optional UDP sequence
inline constexpr std::size_t kPacketWithSequenceBytes = kPacketBytes + kSequenceBytes;  // 1266
inline constexpr std::size_t kMaxPacketBytes = kPacketWithSequenceBytes;
inline constexpr std::uint8_t kMarker0 = 0xFF;             // first marker byte on the wire
inline constexpr std::uint8_t kMarker1 = 0xEE;             // second marker byte on the wire
inline constexpr std::uint16_t kAzimuthLimitCdeg = 36000;  // azimuths are 0..35999
inline constexpr double kDistanceUnitM = 0.004;

// The return mode byte of every Hesai model (at payload offset 1254 in a Pandar40P packet): which
// echoes each firing reports, and so how many blocks one firing fills (returns_per_firing).
// "dual" stays the name of 0x39 (last + strongest), the Pandar40P's name for it since the first
// release: its outputs say "dual". 0x35 and 0x36 are no mode. Each model accepts only its own
// modes (Pandar40P: kPandar40PReturnModes; the others: their kReturnModes, core/sensors/).
enum class ReturnMode : std::uint8_t {
  kFirst = 0x33,
  kSecond = 0x34,
  kStrongest = 0x37,
  kLast = 0x38,
  kDual =
      0x39,  // last + strongest: blocks (2k, 2k+1) share one firing: even = last, odd = strongest
  kFirstSecond = 0x3A,
  kFirstLast = 0x3B,
  kFirstStrongest = 0x3C,
  kFirstLastStrongest = 0x3D,  // three blocks (3k, 3k+1, 3k+2) per firing
  kStrongestSecond = 0x3E,     // strongest + second strongest
};
inline constexpr std::array<ReturnMode, 10> kAllReturnModes = {
    ReturnMode::kFirst,          ReturnMode::kSecond,         ReturnMode::kStrongest,
    ReturnMode::kLast,           ReturnMode::kDual,           ReturnMode::kFirstSecond,
    ReturnMode::kFirstLast,      ReturnMode::kFirstStrongest, ReturnMode::kFirstLastStrongest,
    ReturnMode::kStrongestSecond};
// The modes a Pandar40P sends (MAN40P: last, strongest, last + strongest); validate() rejects
// the others as bad_return_mode.
inline constexpr std::array<ReturnMode, 3> kPandar40PReturnModes = {
    ReturnMode::kStrongest, ReturnMode::kLast, ReturnMode::kDual};

// "first", "second", "strongest", "last", "dual", "first_second", "first_last",
// "first_strongest", "first_last_strongest", "strongest_second" (the names the JSON outputs
// use); "unknown" for other values.
std::string_view to_string(ReturnMode mode) noexcept;
// Returns the mode for one of the ten mode bytes, nullopt otherwise.
std::optional<ReturnMode> return_mode_from_byte(std::uint8_t value) noexcept;
// Parses one of the ten names above.
std::optional<ReturnMode> return_mode_from_string(std::string_view name) noexcept;
// Echoes per firing: 1 (single modes), 2 (the dual modes), 3 (first + last + strongest).
inline constexpr int returns_per_firing(ReturnMode mode) noexcept {
  switch (mode) {
    case ReturnMode::kDual:
    case ReturnMode::kFirstSecond:
    case ReturnMode::kFirstLast:
    case ReturnMode::kFirstStrongest:
    case ReturnMode::kStrongestSecond:
      return 2;
    case ReturnMode::kFirstLastStrongest:
      return 3;
    default:
      return 1;
  }
}
// Whether `mode` is one of `modes` (a model's list of the modes it sends).
template <std::size_t N>
constexpr bool mode_listed(const std::array<ReturnMode, N>& modes, ReturnMode mode) noexcept {
  for (ReturnMode m : modes) {
    if (m == mode) return true;
  }
  return false;
}

// Why a payload was not accepted. Each value is its own counter in the daemon's health output.
enum class RejectReason : std::uint8_t {
  kNone = 0,
  kBadLength,      // not 1262 or 1266 bytes (1256 = legacy Pandar40, 512 = GPS packet, ...); for
                   // the other models: not a length their header's flags allow
  kBadMarker,      // some block does not start with FF EE (other models: no EE FF start)
  kBadAzimuth,     // some block azimuth >= 36000
  kBadReturnMode,  // return mode byte not one the model sends (Pandar40P: 0x37/0x38/0x39)
  // New values go at the end: the names are JSON keys and the numbers index counters.
  kBadCrc,      // a CRC the packet carries does not match its bytes (PandarQT128)
  kWrongModel,  // the header names another model: protocol version, laser or block count
  // A Hesai model pandarcap knows of and does not decode (AT128, OT128, ...: model_detection.hpp):
  // counted, never decoded as garbage.
  kUnsupportedModel,
};
inline constexpr std::size_t kRejectReasonCount = 8;
// Stable snake_case name, used as a JSON key and a Prometheus label value ("bad_length", ...).
std::string_view to_string(RejectReason reason) noexcept;

// Checks length, all ten markers, all ten azimuths and the return mode. Reads only inside
// `payload`. Out-of-range tail date fields do not reject a packet (see Tail::time_valid).
RejectReason validate(std::span<const std::uint8_t> payload) noexcept;

inline std::uint16_t load_u16_le(const std::uint8_t* p) noexcept {
  return static_cast<std::uint16_t>(p[0] | (p[1] << 8));
}
inline std::uint32_t load_u32_le(const std::uint8_t* p) noexcept {
  return static_cast<std::uint32_t>(p[0]) | (static_cast<std::uint32_t>(p[1]) << 8) |
         (static_cast<std::uint32_t>(p[2]) << 16) | (static_cast<std::uint32_t>(p[3]) << 24);
}

// UTC date and time from the tail: one binary byte each (not BCD).
struct TailDateTime {
  std::uint8_t year_since_2000 = 0;  // 17 = 2017
  std::uint8_t month = 0;            // 1..12
  std::uint8_t day = 0;              // 1..31
  std::uint8_t hour = 0;             // 0..23
  std::uint8_t minute = 0;           // 0..59
  std::uint8_t second = 0;           // 0..59 (60 accepted: a leap second)
  friend bool operator==(const TailDateTime&, const TailDateTime&) = default;
};

// The 22-byte tail (+ optional sequence), decoded. Spec §1.3.
struct Tail {
  std::uint16_t status_value = 0;     // rotating status word (meaning depends on status_id)
  std::uint8_t status_id = 0;         // 0..22 observed
  std::uint8_t reserved_opaque[2]{};  // unit-specific, meaning unknown
  bool high_temperature = false;      // shutdown flag: sensor stops 60 s after it is set
  std::uint16_t error_code = 0;       // "reserved" in the manual; 0 observed
  std::uint16_t motor_rpm = 0;        // measured spin rate, plain RPM (600 at 10 Hz)
  std::uint32_t timestamp_us = 0;     // microseconds within the UTC second, 0..1'000'000
  std::uint8_t return_mode_byte = 0;  // 0x37 / 0x38 / 0x39
  std::uint8_t factory = 0;           // 0x42 (or 0x43)
  TailDateTime utc;
  std::optional<std::uint32_t> sequence;  // only in 1266-byte packets
};

// Read-only view of a validated payload. Cheap to copy; does not own the bytes.
class PacketView {
 public:
  // Returns a view when validate() accepts the payload, nullopt otherwise.
  static std::optional<PacketView> make(std::span<const std::uint8_t> payload) noexcept {
    if (validate(payload) != RejectReason::kNone) return std::nullopt;
    return PacketView(payload);
  }
  // For callers that already validated (the decode worker validates once, then views).
  static PacketView assume_valid(std::span<const std::uint8_t> payload) noexcept {
    return PacketView(payload);
  }

  std::span<const std::uint8_t> bytes() const noexcept { return bytes_; }
  bool has_sequence() const noexcept { return bytes_.size() == kPacketWithSequenceBytes; }

  const std::uint8_t* block(int b) const noexcept { return bytes_.data() + kBlockBytes * b; }
  std::uint16_t azimuth_cdeg(int b) const noexcept { return load_u16_le(block(b) + 2); }
  std::uint16_t distance_raw(int b, int c) const noexcept {
    return load_u16_le(block(b) + 4 + 3 * c);
  }
  std::uint8_t reflectivity(int b, int c) const noexcept { return block(b)[6 + 3 * c]; }

  const std::uint8_t* tail_bytes() const noexcept { return bytes_.data() + kBodyBytes; }
  std::uint16_t motor_rpm() const noexcept { return load_u16_le(tail_bytes() + 8); }
  std::uint32_t timestamp_us() const noexcept { return load_u32_le(tail_bytes() + 10); }
  ReturnMode return_mode() const noexcept { return static_cast<ReturnMode>(tail_bytes()[14]); }
  TailDateTime utc() const noexcept {
    const std::uint8_t* t = tail_bytes() + 16;
    return {t[0], t[1], t[2], t[3], t[4], t[5]};
  }
  std::optional<std::uint32_t> sequence() const noexcept {
    if (!has_sequence()) return std::nullopt;
    return load_u32_le(bytes_.data() + kPacketBytes);
  }
  Tail tail() const noexcept;

 private:
  explicit PacketView(std::span<const std::uint8_t> bytes) noexcept : bytes_(bytes) {}
  std::span<const std::uint8_t> bytes_;
};

}  // namespace pandarcap
