// Times since the Unix epoch as text, in UTC: the health record's "time" and the PCD header's
// reference time share one formatter.
#pragma once

#include <cstdint>
#include <string>

namespace pandarcap {

// ns since the epoch as whole seconds and the nanoseconds after them (0..999'999'999), floored:
// -1 ns is second -1 and 999'999'999 ns.
struct UnixTime {
  std::int64_t seconds = 0;
  std::int64_t nanoseconds = 0;
};
UnixTime split_unix_ns(std::int64_t unix_ns) noexcept;

// Appends RFC 3339 in UTC with `fraction_digits` (1..9) digits of the second, truncated:
// "2026-11-22T12:00:00.123Z" for 3. No allocation once `out` has room.
void append_rfc3339(std::string& out, std::int64_t unix_ns, int fraction_digits);

// The stamp in the outputs' file names: "20261122T120000.123Z" (with_millis) or
// "20261122T120000Z". No allocation once `out` has room (the frames' names, every frame).
void append_utc_file_stamp(std::string& out, std::int64_t unix_ns, bool with_millis);
std::string utc_file_stamp(std::int64_t unix_ns, bool with_millis);

}  // namespace pandarcap
