// The zero-loss harness's clean-up on a signal (bench/stop_on_signal): its handler runs in the
// harness only, never in a child stopped between its fork and its exec, and a guard that is gone
// does not take the harness with it. CI's release job once saw the harness die of SIGPIPE when a
// SIGINT came as a trial's daemon had just been forked (the end-to-end test in test_bench_cli.cpp
// caught it one run in four); these reach that moment every time.
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "bench/child_process.hpp"
#include "bench/stop_on_signal.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
using bench::StopOnSignal;
using harness::ChildProcess;

namespace {

// A guard's command: appends a line to `marker` each time it runs.
std::vector<std::vector<std::string>> append_to(const std::filesystem::path& marker) {
  return {{"/bin/sh", "-c", "echo ran >> \"$1\"", "sh", marker.string()}};
}

// Process `pid`'s state and parent (/proc/PID/stat, after the name, which may hold spaces); an
// empty state when it is gone.
std::pair<std::string, int> state_and_parent(int pid) {
  const std::string line = harness::read_file("/proc/" + std::to_string(pid) + "/stat");
  const auto close = line.rfind(')');
  if (close == std::string::npos) return {"", 0};
  std::istringstream fields(line.substr(close + 2));
  std::pair<std::string, int> result;
  fields >> result.first >> result.second;
  return result;
}

// The pids of this process's children that are still this program (forked, never exec'd): the
// guards.
std::vector<int> forked_children() {
  std::vector<int> pids;
  const std::string self = std::filesystem::read_symlink("/proc/self/exe").string();
  for (const int pid : test::process_ids()) {
    std::error_code ec;
    const auto exe = std::filesystem::read_symlink("/proc/" + std::to_string(pid) + "/exe", ec);
    if (state_and_parent(pid).second == ::getpid() && exe == self) pids.push_back(pid);
  }
  return pids;
}

}  // namespace

// Each child is signalled right after its fork, while the harness holds the signals (as
// zero-loss does until the daemon is registered): the child has them held too and gets this one
// when it lets them through, before its exec, with the harness's handler still in place unless
// the child drops it first. The handler there would tell the guard to run its commands.
TEST_CASE("a child signalled between its fork and its exec never runs the harness's stop handler",
          "[bench][signals]") {
  test::ScratchDir dir("stop-on-signal-children");
  const auto marker = dir / "guard-ran";
  StopOnSignal stop;
  const int guard = stop.guard(append_to(marker));
  for (const int signal_number : {SIGTERM, SIGINT}) {
    for (int i = 0; i < 50; ++i) {
      std::optional<ChildProcess> child;
      {
        const StopOnSignal::Held held;
        child.emplace("/bin/true", std::vector<std::string>{}, dir / "child.log");
        ::kill(child->pid(), signal_number);
      }
      const std::optional<int> status = child->wait_exit(std::chrono::seconds(10));
      INFO("signal " << signal_number << ", child " << i);
      REQUIRE(status);
      // Killed by it (the default action), or it had run /bin/true to the end already.
      CHECK((*status == -signal_number || *status == 0));
      REQUIRE_FALSE(std::filesystem::exists(marker));
    }
  }
  // The guard is still there, untold, and runs its commands once when asked.
  stop.run_guarded_now(guard);
  CHECK(harness::read_file(marker) == "ran\n");
}

// A guard killed from outside (the OOM killer, a user's kill -9): telling it must not raise
// SIGPIPE in the harness, and the other guards still run their commands.
TEST_CASE("a guard killed from outside leaves the harness and the other guards working",
          "[bench][signals]") {
  test::ScratchDir dir("stop-on-signal-killed-guard");
  const auto first = dir / "first-ran";
  const auto second = dir / "second-ran";
  std::optional<StopOnSignal> stop;
  stop.emplace();
  const int first_guard = stop->guard(append_to(first));
  const std::vector<int> before = forked_children();
  REQUIRE(before.size() == 1);
  const int second_guard = stop->guard(append_to(second));
  ::kill(before.front(), SIGKILL);
  // The killed guard's end is what the harness then writes to; waits for the kill to land.
  REQUIRE(harness::wait_until([&] { return state_and_parent(before.front()).first == "Z"; },
                              std::chrono::seconds(10)));
  stop->run_guarded_now(first_guard);  // a dead guard: nothing runs, the harness lives on
  CHECK_FALSE(std::filesystem::exists(first));
  stop->run_guarded_now(second_guard);
  CHECK(harness::read_file(second) == "ran\n");
  stop.reset();  // tells no guard twice
  CHECK(forked_children().empty());
}

// A signal the harness was started ignoring stays ignored (a script's `cmd &` ignores SIGINT,
// nohup SIGHUP); the others get the handler while it lives and what they had back after.
TEST_CASE("the stop handler leaves an ignored signal ignored and restores the others",
          "[bench][signals]") {
  const auto handler_of = [](int signal_number) {
    struct sigaction current {};
    ::sigaction(signal_number, nullptr, &current);
    return current.sa_handler;
  };
  for (const int ignored : {SIGINT, SIGTERM, SIGHUP}) {
    CAPTURE(ignored);
    struct sigaction before[3]{};
    const int stopping[3] = {SIGINT, SIGTERM, SIGHUP};
    for (int i = 0; i < 3; ++i)
      ::sigaction(stopping[i], nullptr, &before[i]);
    ::signal(ignored, SIG_IGN);
    {
      const StopOnSignal stop;
      for (int i = 0; i < 3; ++i) {
        CAPTURE(stopping[i]);
        if (stopping[i] == ignored) {
          CHECK(handler_of(stopping[i]) == SIG_IGN);
        } else {
          CHECK(handler_of(stopping[i]) != SIG_IGN);
          CHECK(handler_of(stopping[i]) != before[i].sa_handler);
        }
      }
    }
    CHECK(handler_of(ignored) == SIG_IGN);
    for (int i = 0; i < 3; ++i) {
      if (stopping[i] != ignored) CHECK(handler_of(stopping[i]) == before[i].sa_handler);
      ::sigaction(stopping[i], &before[i], nullptr);
    }
  }
}
