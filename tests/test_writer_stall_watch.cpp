// The main thread's judgement of a stalled writer (daemon/output/writer_stall_watch.hpp), on a
// clock of the test's own: a heartbeat that stands for 2 s of running time is a stall; a pause
// of the whole process (SIGSTOP, a frozen cgroup) is not the writer's.
#include <catch2/catch.hpp>

#include "daemon/output/writer_stall_watch.hpp"

namespace pandarcap {
namespace {

using namespace std::chrono_literals;
using Clock = WriterStallWatch::Clock;

const Clock::time_point t0{};

// The watch looking every 500 ms from `from` to `to` (inclusive) with heartbeat `beat`: the
// first look that says stalled, or nothing.
std::optional<Clock::duration> first_stall(WriterStallWatch& watch, Clock::duration from,
                                           Clock::duration to, std::uint64_t beat,
                                           Clock::duration* at = nullptr) {
  for (Clock::duration t = from; t <= to; t += 500ms) {
    if (const auto stood = watch.look(t0 + t, beat)) {
      if (at != nullptr) *at = t;
      return stood;
    }
  }
  return std::nullopt;
}

}  // namespace

TEST_CASE("writer stall watch: 2 s of standing heartbeat is a stall, a beat ends it",
          "[reliability]") {
  WriterStallWatch watch(t0, 500ms, 7);
  Clock::duration at{};
  const auto stood = first_stall(watch, 500ms, 5s, 7, &at);
  REQUIRE(stood);
  CHECK(at == 2s);
  CHECK(*stood == 2s);
  CHECK(watch.look(t0 + 2500ms, 7) == Clock::duration(2500ms));  // and still, growing
  CHECK_FALSE(watch.look(t0 + 3s, 8));                           // a beat: not stalled
  CHECK_FALSE(watch.look(t0 + 4500ms, 8));
  CHECK(watch.look(t0 + 5s, 8) == Clock::duration(2s));  // standing again from 3 s
}

TEST_CASE("writer stall watch: a pause of the whole process is not a stall", "[reliability]") {
  // Beats until 1 s, then the process is stopped from ~1.2 s to 3.4 s: the main thread's next
  // look comes 2.4 s after its last. Before the watch, that look said "stalled for 2.4 s".
  // (A look later than the tick by a second or less is a busy main thread, not a pause: counted.)
  for (const auto pause : {1600ms, 2400ms, 10'000ms, 600'000ms}) {
    CAPTURE(pause.count());
    WriterStallWatch watch(t0, 500ms, 1);
    CHECK_FALSE(watch.look(t0 + 500ms, 2));
    CHECK_FALSE(watch.look(t0 + 1s, 3));
    const auto resumed = t0 + 1s + pause;
    CHECK_FALSE(watch.look(resumed, 3));
    // The writer still does not beat: a stall once it has stood 2 s of running time after the
    // pause (not counting the gap), a tick later than a stall of running time alone at most.
    std::optional<Clock::duration> stood;
    Clock::duration waited{};
    while (!stood && waited < 5s) {
      waited += 500ms;
      stood = watch.look(resumed + waited, 3);
    }
    REQUIRE(stood);
    CHECK(waited == 2s);
    CHECK(*stood == 2s);
  }
}

TEST_CASE("writer stall watch: a writer stalled before a pause is still stalled after it",
          "[reliability]") {
  WriterStallWatch watch(t0, 500ms, 4);
  REQUIRE(first_stall(watch, 500ms, 2s, 4) == Clock::duration(2s));
  // Paused for 3 s: the stall said before goes on (2 s of running time, the gap left out).
  CHECK(watch.look(t0 + 5s, 4) == Clock::duration(2s));
  CHECK(watch.look(t0 + 5500ms, 4) == Clock::duration(2500ms));
  // Looks a little late (a busy machine: up to a second past the tick) still count whole.
  CHECK(watch.look(t0 + 6900ms, 4) == Clock::duration(3900ms));
}

}  // namespace pandarcap
