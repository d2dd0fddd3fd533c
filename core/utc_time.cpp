#include "core/utc_time.hpp"

#include <fmt/format.h>

#include <ctime>
#include <iterator>

namespace pandarcap {

UnixTime split_unix_ns(std::int64_t unix_ns) noexcept {
  constexpr std::int64_t kNs = 1'000'000'000;
  const std::int64_t seconds = unix_ns >= 0 ? unix_ns / kNs : -((-unix_ns + kNs - 1) / kNs);
  return UnixTime{seconds, unix_ns - seconds * kNs};
}

void append_rfc3339(std::string& out, std::int64_t unix_ns, int fraction_digits) {
  const UnixTime t = split_unix_ns(unix_ns);
  const auto seconds = static_cast<std::time_t>(t.seconds);
  std::tm tm{};
  gmtime_r(&seconds, &tm);
  std::int64_t fraction = t.nanoseconds;
  for (int d = fraction_digits; d < 9; ++d)
    fraction /= 10;
  fmt::format_to(std::back_inserter(out), "{:04}-{:02}-{:02}T{:02}:{:02}:{:02}.{:0{}}Z",
                 tm.tm_year + 1900, tm.tm_mon + 1, tm.tm_mday, tm.tm_hour, tm.tm_min, tm.tm_sec,
                 fraction, fraction_digits);
}

void append_utc_file_stamp(std::string& out, std::int64_t unix_ns, bool with_millis) {
  const UnixTime t = split_unix_ns(unix_ns);
  const auto seconds = static_cast<std::time_t>(t.seconds);
  std::tm tm{};
  gmtime_r(&seconds, &tm);
  fmt::format_to(std::back_inserter(out), "{:04}{:02}{:02}T{:02}{:02}{:02}", tm.tm_year + 1900,
                 tm.tm_mon + 1, tm.tm_mday, tm.tm_hour, tm.tm_min, tm.tm_sec);
  if (with_millis) fmt::format_to(std::back_inserter(out), ".{:03}", t.nanoseconds / 1'000'000);
  out += 'Z';
}

std::string utc_file_stamp(std::int64_t unix_ns, bool with_millis) {
  std::string stamp;
  append_utc_file_stamp(stamp, unix_ns, with_millis);
  return stamp;
}

}  // namespace pandarcap
