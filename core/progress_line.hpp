// The progress a long replay or conversion shows on a terminal: how far through the file, how
// fast, how long to go. Pure: the caller gives the time and the counts, and prints the line
// (pandarcapd does, on stderr, only when it is a terminal and not systemd's journal).
//
//   "replay: 42% (12.3 of 29.3 MB), 18000 packets/s, 3 s left"
//
// Nothing for the first `quiet_s` seconds (a short replay says nothing), then a line at most
// every `interval_s`. The rate and the time left are over the whole run so far.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

namespace pandarcap {

class ProgressLine {
 public:
  explicit ProgressLine(double quiet_s = 2.0, double interval_s = 0.5)
      : quiet_s_(quiet_s), interval_s_(interval_s) {}

  // `elapsed_s` since the start; `done_bytes` of `total_bytes` read; `packets` so far.
  std::optional<std::string> update(double elapsed_s, std::uint64_t done_bytes,
                                    std::uint64_t total_bytes, std::uint64_t packets);
  // Whether a line was ever given (the caller then ends it with a newline).
  bool shown() const noexcept { return shown_; }

 private:
  double quiet_s_, interval_s_;
  double last_s_ = -1;
  bool shown_ = false;
};

}  // namespace pandarcap
