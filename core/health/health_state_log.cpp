#include "core/health/health_state_log.hpp"

#include <fmt/format.h>

namespace pandarcap {

std::optional<HealthStateLogLine> HealthStateLog::update(HealthState state, std::string_view reason,
                                                         double now_seconds) {
  if (!start_s_) start_s_ = now_seconds;
  // Waiting for the first packet is how every start begins, not news.
  if (!any_logged_ && state == HealthState::kNoData && now_seconds - *start_s_ < grace_s_)
    return std::nullopt;
  if (state != seen_) {
    ++changes_not_logged_;
    seen_ = state;
  }
  if (state == logged_) {
    // Back where the journal left it before anything else was logged: nothing to say, and the
    // flapping in between is told with the next line.
    return std::nullopt;
  }
  if (any_logged_ && now_seconds - logged_at_s_ < min_interval_s_) return std::nullopt;

  HealthStateLogLine line;
  // This change was counted too; the others are the ones not told.
  const unsigned untold = changes_not_logged_ > 0 ? changes_not_logged_ - 1 : 0;
  if (state == HealthState::kOk) {
    line.text = fmt::format("health: ok again after {:.0f} s {}", now_seconds - logged_at_s_,
                            to_string(logged_));
  } else {
    line.warning = true;
    line.text = fmt::format("health: {}: {}", to_string(state), reason);
  }
  if (untold > 0) {
    fmt::format_to(std::back_inserter(line.text), " ({} state change{} before this not logged)",
                   untold, untold == 1 ? "" : "s");
  }
  logged_ = state;
  logged_at_s_ = now_seconds;
  any_logged_ = true;
  changes_not_logged_ = 0;
  return line;
}

}  // namespace pandarcap
