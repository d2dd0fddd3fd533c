// Absolute packet time: t0 = UTC(tail date-time) + tail microseconds (spec §1.4).
//
// Computed without timegm() and independent of the host's time zone (civil-date arithmetic), and
// the date conversion is cached per distinct 6-byte date, so the work per packet is one compare.
//
// Odd clocks are common (sensors without GPS/PTP send 2017-09-06 ...; broken ones send month 0):
// a packet whose date or microseconds are out of range keeps its points, but its time is marked
// invalid and the caller counts the anomaly.
#pragma once

#include <cstdint>
#include <string_view>

#include "core/sensors/packet.hpp"

namespace pandarcap {

// Days since 1970-01-01 of a proleptic Gregorian date (year e.g. 2017, month 1..12, day 1..31).
// Pure arithmetic, valid for any date the tail can carry.
std::int64_t days_from_civil(int year, unsigned month, unsigned day) noexcept;

// Inverse of days_from_civil + time of day: the tail date-time of a Unix time in seconds.
// Years outside 2000..2255 cannot be represented and are clamped to that range's ends.
TailDateTime tail_datetime_from_unix(std::int64_t unix_seconds) noexcept;

// True when every field is in range for a real calendar date (leap years included; second 60 is
// accepted as a leap second).
bool is_valid(const TailDateTime& utc) noexcept;

// A tail time's first field out of range, in the tail's order (the health's reason names it:
// "month 31"); the year byte is always a year (2000-2255).
enum class TimeField : std::uint8_t { kNone, kMonth, kDay, kHour, kMinute, kSecond, kMicroseconds };
std::string_view to_string(TimeField field) noexcept;  // "month", ..., "microseconds"; "" for none
struct InvalidTimeField {
  TimeField field = TimeField::kNone;
  std::uint32_t value = 0;
};
InvalidTimeField first_invalid_field(const TailDateTime& utc, std::uint32_t timestamp_us) noexcept;

enum class PacketTimeStatus : std::uint8_t {
  kValid,
  kBadDate,          // a date-time field is out of range
  kBadMicroseconds,  // microseconds > 1'000'000
};

struct PacketTime {
  // ns since the Unix epoch when valid; otherwise just the microseconds field (so per-point
  // offsets stay meaningful relative to each other).
  std::int64_t t0_ns = 0;
  PacketTimeStatus status = PacketTimeStatus::kValid;
  bool valid() const noexcept { return status == PacketTimeStatus::kValid; }
};

// Converts tail date + microseconds to absolute time, caching the last date's epoch seconds.
class PacketClock {
 public:
  PacketTime convert(const TailDateTime& utc, std::uint32_t timestamp_us) noexcept;

 private:
  bool cached_ = false;
  TailDateTime cached_date_{};
  bool cached_valid_ = false;
  std::int64_t cached_epoch_s_ = 0;
};

}  // namespace pandarcap
