// What the journal says about the health state: one warning with the reason when the state
// leaves ok (no_data, degraded, error), one info line when it comes back, so that
// `journalctl -u pandarcapd@front` tells the story without opening the health file.
//
// Rate-limited: after a line, changes within the next `min_interval_seconds` are not logged one
// by one. When the interval is over, the state then in force is logged if it differs from the
// last one logged, with the number of changes in between ("3 state changes not logged"), so a
// state flapping every second costs two lines per interval and the journal still ends on the
// truth. At start-up, "no packet received yet" is not a change until `startup_grace_seconds`
// have passed: a sensor's first packet takes a moment.
//
// Pure: the caller (the daemon's main thread) feeds every health record's state and reason with
// the time, and logs what comes back.
#pragma once

#include <optional>
#include <string>
#include <string_view>

#include "core/health/health.hpp"

namespace pandarcap {

struct HealthStateLogLine {
  bool warning = false;  // the state left ok (else: it came back)
  std::string text;      // "health: degraded: 2 kernel drops", "health: ok again after 12 s ..."
};

class HealthStateLog {
 public:
  explicit HealthStateLog(double min_interval_seconds = 10, double startup_grace_seconds = 2)
      : min_interval_s_(min_interval_seconds), grace_s_(startup_grace_seconds) {}

  // One health record: its state and reason at `now_seconds` (any monotonic clock). Returns the
  // line to log, if any.
  std::optional<HealthStateLogLine> update(HealthState state, std::string_view reason,
                                           double now_seconds);

 private:
  double min_interval_s_;
  double grace_s_;
  std::optional<double> start_s_;
  HealthState logged_ = HealthState::kOk;  // the state the journal last said (ok before any)
  double logged_at_s_ = 0;
  bool any_logged_ = false;
  HealthState seen_ = HealthState::kOk;  // the state of the previous record
  unsigned changes_not_logged_ = 0;
};

}  // namespace pandarcap
