// When the writer counts as stalled: its heartbeat has stood for kStall of the time this process
// ran. The main thread looks once a tick (daemon/pandarcapd_main.cpp); a tick that comes far
// later than asked means the whole process was not running (SIGSTOP, a debugger, a cgroup
// freezer, a VM paused), and the writer, which was not running either, is not blamed for that
// time: the gap is left out of how long its heartbeat stood. Without this, the first tick after
// a 2 s pause said "writer stalled for 2.2 s: its disk does not answer" whenever it ran before
// the writer had beaten again. Pure logic, so tests drive it with their own clock.
#pragma once

#include <chrono>
#include <cstdint>
#include <optional>

namespace pandarcap {

class WriterStallWatch {
 public:
  using Clock = std::chrono::steady_clock;
  static constexpr std::chrono::seconds kStall{2};

  WriterStallWatch(Clock::time_point start, std::chrono::nanoseconds tick, std::uint64_t beat)
      : tick_(tick), beat_(beat), beat_at_(start), last_look_(start) {}

  // A tick's look at the writer's heartbeat `beat` at `now`: for how long it has stood, if that
  // is a stall (kStall or more of this process's running time), else nothing.
  std::optional<std::chrono::nanoseconds> look(Clock::time_point now, std::uint64_t beat) {
    const auto since_last_look = now - last_look_;
    last_look_ = now;
    if (beat != beat_) {
      beat_ = beat;
      beat_at_ = now;
      return std::nullopt;
    }
    // Far later than the tick asked (a second more): the process was paused. What stood before
    // is kept; none of the time since the last look is counted (when in it the pause began is
    // not known, and a stall said a tick late is better than one said of a pause).
    if (since_last_look > tick_ + std::chrono::seconds(1)) beat_at_ += since_last_look;
    const auto stood = now - beat_at_;
    if (stood >= kStall) return stood;
    return std::nullopt;
  }

 private:
  std::chrono::nanoseconds tick_;
  std::uint64_t beat_;
  Clock::time_point beat_at_;
  Clock::time_point last_look_;
};

}  // namespace pandarcap
