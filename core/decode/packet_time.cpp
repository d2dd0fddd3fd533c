#include "core/decode/packet_time.hpp"

#include <algorithm>

namespace pandarcap {

std::int64_t days_from_civil(int year, unsigned month, unsigned day) noexcept {
  // Shift the year to start in March so the leap day is the last day of the year; then count
  // 400-year eras (146097 days each) and the days inside the era.
  const int y = year - (month <= 2 ? 1 : 0);
  const int era = (y >= 0 ? y : y - 399) / 400;
  const unsigned year_of_era = static_cast<unsigned>(y - era * 400);        // 0..399
  const unsigned month_from_march = month > 2 ? month - 3 : month + 9;      // 0..11
  const unsigned day_of_year = (153 * month_from_march + 2) / 5 + day - 1;  // 0..365
  const unsigned day_of_era =
      year_of_era * 365 + year_of_era / 4 - year_of_era / 100 + day_of_year;  // 0..146096
  return static_cast<std::int64_t>(era) * 146097 + static_cast<std::int64_t>(day_of_era) - 719468;
}

TailDateTime tail_datetime_from_unix(std::int64_t unix_seconds) noexcept {
  constexpr std::int64_t kFirst = 946684800;  // 2000-01-01T00:00:00Z
  constexpr std::int64_t kLast = 9025257599;  // 2255-12-31T23:59:59Z
  unix_seconds = std::clamp(unix_seconds, kFirst, kLast);
  const std::int64_t days = unix_seconds / 86400;
  const std::int64_t second_of_day = unix_seconds % 86400;
  // Inverse of days_from_civil (same March-based era arithmetic).
  const std::int64_t z = days + 719468;
  const std::int64_t era = z / 146097;
  const auto day_of_era = static_cast<unsigned>(z - era * 146097);
  const unsigned year_of_era =
      (day_of_era - day_of_era / 1460 + day_of_era / 36524 - day_of_era / 146096) / 365;
  const unsigned day_of_year =
      day_of_era - (365 * year_of_era + year_of_era / 4 - year_of_era / 100);
  const unsigned month_from_march = (5 * day_of_year + 2) / 153;
  const unsigned day = day_of_year - (153 * month_from_march + 2) / 5 + 1;
  const unsigned month = month_from_march < 10 ? month_from_march + 3 : month_from_march - 9;
  const std::int64_t year =
      static_cast<std::int64_t>(year_of_era) + era * 400 + (month <= 2 ? 1 : 0);
  TailDateTime utc;
  utc.year_since_2000 = static_cast<std::uint8_t>(year - 2000);
  utc.month = static_cast<std::uint8_t>(month);
  utc.day = static_cast<std::uint8_t>(day);
  utc.hour = static_cast<std::uint8_t>(second_of_day / 3600);
  utc.minute = static_cast<std::uint8_t>(second_of_day / 60 % 60);
  utc.second = static_cast<std::uint8_t>(second_of_day % 60);
  return utc;
}

namespace {

bool is_leap(int year) noexcept {
  return (year % 4 == 0 && year % 100 != 0) || year % 400 == 0;
}

unsigned days_in_month(int year, unsigned month) noexcept {
  static constexpr unsigned kDays[12] = {31, 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31};
  return month == 2 && is_leap(year) ? 29 : kDays[month - 1];
}

}  // namespace

bool is_valid(const TailDateTime& utc) noexcept {
  const int year = 2000 + utc.year_since_2000;
  if (utc.month < 1 || utc.month > 12) return false;
  if (utc.day < 1 || utc.day > days_in_month(year, utc.month)) return false;
  return utc.hour <= 23 && utc.minute <= 59 && utc.second <= 60;
}

std::string_view to_string(TimeField field) noexcept {
  switch (field) {
    case TimeField::kNone:
      return "";
    case TimeField::kMonth:
      return "month";
    case TimeField::kDay:
      return "day";
    case TimeField::kHour:
      return "hour";
    case TimeField::kMinute:
      return "minute";
    case TimeField::kSecond:
      return "second";
    case TimeField::kMicroseconds:
      return "microseconds";
  }
  return "";
}

InvalidTimeField first_invalid_field(const TailDateTime& utc, std::uint32_t timestamp_us) noexcept {
  if (utc.month < 1 || utc.month > 12) return {TimeField::kMonth, utc.month};
  if (utc.day < 1 || utc.day > days_in_month(2000 + utc.year_since_2000, utc.month))
    return {TimeField::kDay, utc.day};
  if (utc.hour > 23) return {TimeField::kHour, utc.hour};
  if (utc.minute > 59) return {TimeField::kMinute, utc.minute};
  if (utc.second > 60) return {TimeField::kSecond, utc.second};
  if (timestamp_us > 1'000'000) return {TimeField::kMicroseconds, timestamp_us};
  return {};
}

PacketTime PacketClock::convert(const TailDateTime& utc, std::uint32_t timestamp_us) noexcept {
  if (!cached_ || !(utc == cached_date_)) {
    cached_ = true;
    cached_date_ = utc;
    cached_valid_ = is_valid(utc);
    if (cached_valid_) {
      const std::int64_t days = days_from_civil(2000 + utc.year_since_2000, utc.month, utc.day);
      cached_epoch_s_ = days * 86400 + utc.hour * 3600 + utc.minute * 60 + utc.second;
    }
  }
  PacketTime time;
  time.t0_ns = static_cast<std::int64_t>(timestamp_us) * 1000;
  if (!cached_valid_) {
    time.status = PacketTimeStatus::kBadDate;
  } else if (timestamp_us > 1'000'000) {
    time.status = PacketTimeStatus::kBadMicroseconds;
  } else {
    time.t0_ns += cached_epoch_s_ * 1'000'000'000;
  }
  return time;
}

}  // namespace pandarcap
