// The journal's account of the health state (core/health/health_state_log.hpp): one warning when
// the state leaves ok, one info line when it returns, rate-limited, and never silent about the end.
#include <catch2/catch.hpp>

#include "core/health/health_state_log.hpp"

using namespace pandarcap;

TEST_CASE("state log: a departure from ok warns with the reason, the return says how long",
          "[health][journal]") {
  HealthStateLog log(10, 2);
  CHECK_FALSE(log.update(HealthState::kNoData, "no packet received yet", 0));  // starting
  CHECK_FALSE(log.update(HealthState::kOk, "", 1));                            // ok is no news
  CHECK_FALSE(log.update(HealthState::kOk, "", 2));
  const auto left = log.update(HealthState::kDegraded, "2 kernel drops", 3);
  REQUIRE(left);
  CHECK(left->warning);
  CHECK(left->text == "health: degraded: 2 kernel drops");
  // Staying degraded, even for another reason, is not a change.
  CHECK_FALSE(log.update(HealthState::kDegraded, "1 ring overruns", 4));
  CHECK_FALSE(log.update(HealthState::kDegraded, "2 kernel drops", 14));
  const auto back = log.update(HealthState::kOk, "", 15);
  REQUIRE(back);
  CHECK_FALSE(back->warning);
  CHECK(back->text == "health: ok again after 12 s degraded");
}

TEST_CASE("state log: waiting for the first packet is news only after the grace period",
          "[health][journal]") {
  HealthStateLog log(10, 2);
  CHECK_FALSE(log.update(HealthState::kNoData, "no packet received yet", 100));
  CHECK_FALSE(log.update(HealthState::kNoData, "no packet received yet", 101));
  const auto silent = log.update(HealthState::kNoData, "no packet received yet", 102);
  REQUIRE(silent);
  CHECK(silent->text == "health: no_data: no packet received yet");
  CHECK_FALSE(log.update(HealthState::kNoData, "no packet received yet", 103));
}

TEST_CASE("state log: flapping is rate-limited, counted, and the journal ends on the truth",
          "[health][journal]") {
  HealthStateLog log(10, 2);
  REQUIRE(log.update(HealthState::kOk, "", 0) == std::nullopt);
  REQUIRE(log.update(HealthState::kDegraded, "1 kernel drops", 1));  // logged at once
  // Flapping every second for 8 s: nothing more inside the interval.
  int lines = 0;
  for (int t = 2; t < 11; ++t) {
    if (log.update(t % 2 == 0 ? HealthState::kOk : HealthState::kDegraded, "1 kernel drops", t))
      ++lines;
  }
  CHECK(lines == 0);
  // At t = 11 the interval is over and the state in force (ok) differs from the last logged.
  const auto settled = log.update(HealthState::kOk, "", 11);
  REQUIRE(settled);
  CHECK_FALSE(settled->warning);
  // Nine changes at t = 2..10 (ok at even seconds); the last of them is the one told here.
  CHECK(settled->text ==
        "health: ok again after 10 s degraded (8 state changes before this not "
        "logged)");
  // An error later is logged at once with its own reason.
  const auto error = log.update(HealthState::kError, "3 receive errors: the socket is failing", 30);
  REQUIRE(error);
  CHECK(error->warning);
  CHECK(error->text == "health: error: 3 receive errors: the socket is failing");
}
