// Absolute packet time (spec §1.4): t0 = UTC(tail date-time, year byte + 2000) + tail µs.
// Expected values come from the calendar (hand-counted day numbers) and from the C library's
// timegm()/gmtime_r(), used here only as an oracle.
#include <catch2/catch.hpp>
#include <cstdint>
#include <cstdlib>
#include <ctime>
#include <optional>
#include <string>

#include "core/decode/packet_time.hpp"

using namespace pandarcap;

namespace {

std::int64_t oracle_timegm(int year, int month, int day, int hour = 0, int minute = 0,
                           int second = 0) {
  std::tm tm{};
  tm.tm_year = year - 1900;
  tm.tm_mon = month - 1;
  tm.tm_mday = day;
  tm.tm_hour = hour;
  tm.tm_min = minute;
  tm.tm_sec = second;
  return static_cast<std::int64_t>(timegm(&tm));
}

TailDateTime tail(int year, int month, int day, int hour = 0, int minute = 0, int second = 0) {
  return {static_cast<std::uint8_t>(year - 2000), static_cast<std::uint8_t>(month),
          static_cast<std::uint8_t>(day),         static_cast<std::uint8_t>(hour),
          static_cast<std::uint8_t>(minute),      static_cast<std::uint8_t>(second)};
}

bool is_leap(int year) {
  return (year % 4 == 0 && year % 100 != 0) || year % 400 == 0;
}

int days_in_month(int year, int month) {
  static const int kDays[12] = {31, 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31};
  return month == 2 && is_leap(year) ? 29 : kDays[month - 1];
}

// Sets TZ for the lifetime of the object and restores the previous value.
class ScopedTimeZone {
 public:
  explicit ScopedTimeZone(const char* zone) {
    if (const char* old = std::getenv("TZ")) previous_ = old;
    setenv("TZ", zone, 1);
    tzset();
  }
  ~ScopedTimeZone() {
    if (previous_) {
      setenv("TZ", previous_->c_str(), 1);
    } else {
      unsetenv("TZ");
    }
    tzset();
  }
  ScopedTimeZone(const ScopedTimeZone&) = delete;
  ScopedTimeZone& operator=(const ScopedTimeZone&) = delete;

 private:
  std::optional<std::string> previous_;
};

constexpr std::int64_t kNsPerS = 1'000'000'000;

}  // namespace

TEST_CASE("days_from_civil on known dates", "[time]") {
  CHECK(days_from_civil(1970, 1, 1) == 0);
  CHECK(days_from_civil(1970, 1, 2) == 1);
  CHECK(days_from_civil(1969, 12, 31) == -1);
  // 30 years, 7 leap days (1972 ... 1996).
  CHECK(days_from_civil(2000, 1, 1) == 30 * 365 + 7);
  CHECK(days_from_civil(2000, 1, 1) == 10957);
  // 2017-01-01 = 47 * 365 + 12 leap days = 17167; + 243 days (Jan..Aug) + 5.
  CHECK(days_from_civil(2017, 9, 6) == 17415);
  // 2024-01-01 = 54 * 365 + 13 = 19723; + 31 + 28.
  CHECK(days_from_civil(2024, 2, 29) == 19782);
  CHECK(days_from_civil(2024, 3, 1) == 19783);
  // 2100-01-01 = 130 * 365 + 32 = 47482; + 31 + 28 (2100 is not a leap year).
  CHECK(days_from_civil(2100, 2, 28) == 47540);
  CHECK(days_from_civil(2100, 3, 1) == 47541);
  // The synthetic sensor's default start, 2026-11-22T12:00:00Z = 1 795 348 800 s.
  CHECK(days_from_civil(2026, 11, 22) * 86400 + 12 * 3600 == 1'795'348'800);
}

TEST_CASE("days_from_civil agrees with timegm on every day the tail can carry", "[time]") {
  std::int64_t previous = days_from_civil(1999, 12, 31);
  for (int year = 2000; year <= 2255; ++year) {
    for (int month = 1; month <= 12; ++month) {
      for (int day = 1; day <= days_in_month(year, month); ++day) {
        const std::int64_t days =
            days_from_civil(year, static_cast<unsigned>(month), static_cast<unsigned>(day));
        if (days != oracle_timegm(year, month, day) / 86400) {
          FAIL_CHECK(year << '-' << month << '-' << day << ": " << days);
        }
        if (days != previous + 1) FAIL_CHECK(year << '-' << month << '-' << day << " not +1");
        previous = days;
      }
    }
  }
  CHECK(previous == days_from_civil(2256, 1, 1) - 1);
}

TEST_CASE("tail_datetime_from_unix inverts UTC conversion, incl. month/year ends and leap days",
          "[time]") {
  auto check_second = [](std::int64_t unix_s) {
    const TailDateTime got = tail_datetime_from_unix(unix_s);
    const auto t = static_cast<std::time_t>(unix_s);
    std::tm tm{};
    gmtime_r(&t, &tm);
    const TailDateTime want =
        tail(tm.tm_year + 1900, tm.tm_mon + 1, tm.tm_mday, tm.tm_hour, tm.tm_min, tm.tm_sec);
    if (!(got == want)) {
      FAIL_CHECK(unix_s << ": got " << int(got.year_since_2000) << '-' << int(got.month) << '-'
                        << int(got.day) << ' ' << int(got.hour) << ':' << int(got.minute) << ':'
                        << int(got.second));
    }
  };
  const std::int64_t first_day = days_from_civil(2000, 1, 1);
  const std::int64_t last_day = days_from_civil(2255, 12, 31);
  for (std::int64_t day = first_day; day <= last_day; ++day) {
    // First and last second of every day, plus one inside it that moves through the day.
    const std::int64_t base = day * 86400;
    check_second(base);
    check_second(base + 86399);
    check_second(base + (day * 7919) % 86400);
  }
  // Named edges, and the round trip through the clock.
  for (const TailDateTime& edge :
       {tail(2000, 1, 1), tail(2000, 2, 29, 23, 59, 59), tail(2000, 12, 31, 23, 59, 59),
        tail(2017, 9, 6, 16, 19, 46), tail(2024, 2, 29, 12), tail(2099, 12, 31, 23, 59, 59),
        tail(2100, 2, 28, 23, 59, 59), tail(2100, 3, 1), tail(2255, 12, 31, 23, 59, 59)}) {
    PacketClock clock;
    const PacketTime t = clock.convert(edge, 0);
    REQUIRE(t.valid());
    CHECK(tail_datetime_from_unix(t.t0_ns / kNsPerS) == edge);
  }
  // The day after 2100-02-28 is March 1st: 2100 is not a leap year.
  CHECK(tail_datetime_from_unix(oracle_timegm(2100, 2, 28, 23, 59, 59) + 1) == tail(2100, 3, 1));
  CHECK(tail_datetime_from_unix(oracle_timegm(2024, 2, 28, 23, 59, 59) + 1) == tail(2024, 2, 29));
}

TEST_CASE("tail_datetime_from_unix clamps to what the tail can carry", "[time]") {
  CHECK(tail_datetime_from_unix(0) == tail(2000, 1, 1));
  CHECK(tail_datetime_from_unix(oracle_timegm(1999, 12, 31, 23, 59, 59)) == tail(2000, 1, 1));
  CHECK(tail_datetime_from_unix(-1'000'000'000) == tail(2000, 1, 1));
  CHECK(tail_datetime_from_unix(oracle_timegm(2256, 1, 1)) == tail(2255, 12, 31, 23, 59, 59));
  CHECK(tail_datetime_from_unix(INT64_C(1) << 40) == tail(2255, 12, 31, 23, 59, 59));
}

TEST_CASE("is_valid: field ranges and leap years", "[time]") {
  CHECK(is_valid(tail(2017, 9, 6, 16, 19, 46)));
  CHECK(is_valid(tail(2000, 1, 1)));
  CHECK(is_valid(tail(2255, 12, 31, 23, 59, 59)));

  SECTION("month") {
    CHECK_FALSE(is_valid(tail(2017, 0, 6)));
    CHECK(is_valid(tail(2017, 1, 6)));
    CHECK(is_valid(tail(2017, 12, 6)));
    CHECK_FALSE(is_valid(tail(2017, 13, 6)));
    CHECK_FALSE(is_valid(tail(2017, 255, 6)));
  }
  SECTION("day") {
    CHECK_FALSE(is_valid(tail(2017, 9, 0)));
    CHECK(is_valid(tail(2017, 1, 31)));
    CHECK_FALSE(is_valid(tail(2017, 1, 32)));
    CHECK(is_valid(tail(2017, 9, 30)));
    CHECK_FALSE(is_valid(tail(2017, 9, 31)));  // September has 30 days
    CHECK_FALSE(is_valid(tail(2017, 4, 31)));
    CHECK(is_valid(tail(2017, 12, 31)));
  }
  SECTION("February 29th only in leap years") {
    CHECK(is_valid(tail(2024, 2, 29)));
    CHECK(is_valid(tail(2000, 2, 29)));  // divisible by 400
    CHECK_FALSE(is_valid(tail(2023, 2, 29)));
    CHECK_FALSE(is_valid(tail(2100, 2, 29)));  // divisible by 100, not by 400
    CHECK_FALSE(is_valid(tail(2200, 2, 29)));
    CHECK(is_valid(tail(2100, 2, 28)));
    CHECK_FALSE(is_valid(tail(2024, 2, 30)));
  }
  SECTION("time of day; second 60 is a leap second") {
    CHECK(is_valid(tail(2017, 9, 6, 23, 0, 0)));
    CHECK_FALSE(is_valid(tail(2017, 9, 6, 24, 0, 0)));
    CHECK(is_valid(tail(2017, 9, 6, 0, 59, 0)));
    CHECK_FALSE(is_valid(tail(2017, 9, 6, 0, 60, 0)));
    CHECK(is_valid(tail(2017, 9, 6, 0, 0, 59)));
    CHECK(is_valid(tail(2016, 12, 31, 23, 59, 60)));
    CHECK_FALSE(is_valid(tail(2017, 9, 6, 0, 0, 61)));
  }
  SECTION("every day of 2000..2255 that the calendar has, and none it lacks") {
    for (int year = 2000; year <= 2255; ++year) {
      for (int month = 1; month <= 12; ++month) {
        for (int day = 1; day <= 31; ++day) {
          const bool want = day <= days_in_month(year, month);
          if (is_valid(tail(year, month, day)) != want) {
            FAIL_CHECK(year << '-' << month << '-' << day << " should be "
                            << (want ? "valid" : "invalid"));
          }
        }
      }
    }
  }
}

TEST_CASE("PacketClock: t0 = UTC date-time + µs", "[time]") {
  PacketClock clock;
  // The nebula capture's date (spec §1.4), 2017-09-06 16:19:46 + 999 910 µs.
  const PacketTime t = clock.convert(tail(2017, 9, 6, 16, 19, 46), 999'910);
  CHECK(t.status == PacketTimeStatus::kValid);
  CHECK(t.valid());
  const std::int64_t epoch_s = INT64_C(17415) * 86400 + 16 * 3600 + 19 * 60 + 46;
  CHECK(t.t0_ns == epoch_s * kNsPerS + 999'910'000);
  // The µs field rolls to 188 when the seconds byte increments: t0 advances by 90 278 µs.
  const PacketTime next = clock.convert(tail(2017, 9, 6, 16, 19, 47), 188);
  CHECK(next.valid());
  CHECK(next.t0_ns - t.t0_ns == (1'000'000 - 999'910 + 188) * 1000);

  SECTION("many dates against timegm") {
    for (int year = 2000; year <= 2255; year += 7) {
      for (int month = 1; month <= 12; ++month) {
        const int day = 1 + (year + month * 3) % days_in_month(year, month);
        const int hour = (year + month) % 24, minute = (year * month) % 60, second = month * 4;
        const std::uint32_t us = static_cast<std::uint32_t>(year * 3779 + month) % 1'000'000;
        const PacketTime p = clock.convert(tail(year, month, day, hour, minute, second), us);
        REQUIRE(p.valid());
        CHECK(p.t0_ns == oracle_timegm(year, month, day, hour, minute, second) * kNsPerS +
                             static_cast<std::int64_t>(us) * 1000);
      }
    }
  }
}

TEST_CASE("PacketClock: µs up to 1'000'000 is accepted, more is kBadMicroseconds", "[time]") {
  PacketClock clock;
  const TailDateTime date = tail(2024, 2, 29, 12, 30, 15);
  const std::int64_t epoch_s = oracle_timegm(2024, 2, 29, 12, 30, 15);

  const PacketTime zero = clock.convert(date, 0);
  CHECK(zero.valid());
  CHECK(zero.t0_ns == epoch_s * kNsPerS);

  const PacketTime full = clock.convert(date, 1'000'000);
  CHECK(full.status == PacketTimeStatus::kValid);
  CHECK(full.t0_ns == (epoch_s + 1) * kNsPerS);

  const PacketTime over = clock.convert(date, 1'000'001);
  CHECK(over.status == PacketTimeStatus::kBadMicroseconds);
  CHECK_FALSE(over.valid());
  CHECK(over.t0_ns == 1'000'001'000);  // only the µs field, as documented

  const PacketTime huge = clock.convert(date, 0xFFFFFFFFu);
  CHECK(huge.status == PacketTimeStatus::kBadMicroseconds);
  CHECK(huge.t0_ns == INT64_C(0xFFFFFFFF) * 1000);

  // A bad µs field does not poison the date: the next packet is valid again.
  const PacketTime after = clock.convert(date, 500'000);
  CHECK(after.valid());
  CHECK(after.t0_ns == epoch_s * kNsPerS + 500'000'000);
}

TEST_CASE("PacketClock: a bad date gives kBadDate and t0 = µs only", "[time]") {
  const TailDateTime bad_dates[] = {tail(2017, 0, 6),
                                    tail(2017, 13, 6),
                                    tail(2017, 9, 0),
                                    tail(2017, 9, 31),
                                    tail(2023, 2, 29),
                                    tail(2100, 2, 29),
                                    tail(2017, 9, 6, 24),
                                    tail(2017, 9, 6, 10, 60),
                                    tail(2017, 9, 6, 10, 0, 61),
                                    TailDateTime{0, 0, 0, 0, 0, 0}};
  for (const TailDateTime& date : bad_dates) {
    INFO("month " << int(date.month) << " day " << int(date.day) << " hour " << int(date.hour)
                  << " minute " << int(date.minute) << " second " << int(date.second));
    PacketClock clock;
    const PacketTime t = clock.convert(date, 123'456);
    CHECK(t.status == PacketTimeStatus::kBadDate);
    CHECK_FALSE(t.valid());
    CHECK(t.t0_ns == 123'456'000);
    // Still bad from the cache.
    const PacketTime again = clock.convert(date, 654'321);
    CHECK(again.status == PacketTimeStatus::kBadDate);
    CHECK(again.t0_ns == 654'321'000);
  }
  // A leap second is a valid date: 2016-12-31 23:59:60 is one second after 23:59:59.
  PacketClock clock;
  const PacketTime leap = clock.convert(tail(2016, 12, 31, 23, 59, 60), 0);
  CHECK(leap.valid());
  CHECK(leap.t0_ns == (oracle_timegm(2016, 12, 31, 23, 59, 59) + 1) * kNsPerS);
}

TEST_CASE("PacketClock does not depend on the host time zone", "[time]") {
  const TailDateTime date = tail(2017, 9, 6, 16, 19, 46);  // daylight saving time in New York
  const TailDateTime winter = tail(2024, 1, 15, 3, 4, 5);
  const std::int64_t want = (INT64_C(17415) * 86400 + 16 * 3600 + 19 * 60 + 46) * kNsPerS + 42'000;
  const std::int64_t want_winter = oracle_timegm(2024, 1, 15, 3, 4, 5) * kNsPerS + 42'000;
  for (const char* zone : {"America/New_York", "Asia/Kolkata", "Pacific/Chatham", "UTC0"}) {
    INFO("TZ=" << zone);
    const ScopedTimeZone scoped(zone);
    // The zone really is in effect (a missing zone file would silently mean UTC).
    std::time_t probe = static_cast<std::time_t>(want / kNsPerS);
    std::tm local{};
    localtime_r(&probe, &local);
    CHECK((local.tm_gmtoff != 0) == (std::string(zone) != "UTC0"));
    PacketClock clock;
    CHECK(clock.convert(date, 42).t0_ns == want);
    CHECK(clock.convert(winter, 42).t0_ns == want_winter);
    CHECK(tail_datetime_from_unix(want / kNsPerS) == date);
    CHECK(days_from_civil(2017, 9, 6) == 17415);
  }
}

TEST_CASE("a cached date gives the same results as a fresh clock", "[time]") {
  // Dates that differ in one field only, visited back and forth, so a cache keyed on part of
  // the date (or not invalidated) would return a stale epoch.
  const TailDateTime dates[] = {
      tail(2017, 9, 6, 16, 19, 46),  tail(2017, 9, 6, 16, 19, 47),  tail(2017, 9, 6, 16, 20, 47),
      tail(2017, 9, 6, 17, 20, 47),  tail(2017, 9, 7, 17, 20, 47),  tail(2017, 10, 7, 17, 20, 47),
      tail(2018, 10, 7, 17, 20, 47), tail(2018, 13, 7, 17, 20, 47),  // bad month
      tail(2018, 2, 29, 17, 20, 47),                                 // bad day
  };
  PacketClock cached;
  std::uint32_t us = 0;
  for (int round = 0; round < 3; ++round) {
    for (int i = 0; i < 9; ++i) {
      // Forwards, then backwards, then skipping.
      const int k = round == 1 ? 8 - i : round == 2 ? (i * 4) % 9 : i;
      for (int repeat = 0; repeat < 3; ++repeat) {
        us = (us + 277'800) % 1'000'001;
        PacketClock fresh;
        const PacketTime a = cached.convert(dates[k], us);
        const PacketTime b = fresh.convert(dates[k], us);
        INFO("date " << k << " µs " << us);
        CHECK(a.status == b.status);
        CHECK(a.t0_ns == b.t0_ns);
      }
    }
  }
  // And the fresh results are the right ones, not merely equal.
  PacketClock fresh;
  CHECK(fresh.convert(dates[1], 0).t0_ns - fresh.convert(dates[0], 0).t0_ns == kNsPerS);
  CHECK(fresh.convert(dates[2], 0).t0_ns - fresh.convert(dates[1], 0).t0_ns == 60 * kNsPerS);
  CHECK(fresh.convert(dates[3], 0).t0_ns - fresh.convert(dates[2], 0).t0_ns == 3600 * kNsPerS);
  CHECK(fresh.convert(dates[4], 0).t0_ns - fresh.convert(dates[3], 0).t0_ns == 86400 * kNsPerS);
  CHECK(fresh.convert(dates[7], 0).status == PacketTimeStatus::kBadDate);
  CHECK(fresh.convert(dates[8], 0).status == PacketTimeStatus::kBadDate);
}
