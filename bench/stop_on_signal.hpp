// What a zero-loss run leaves behind when SIGINT, SIGTERM or SIGHUP stops it: nothing. While a
// StopOnSignal lives, those signals (each one the harness was not started ignoring: a script's
// background job ignores SIGINT, nohup SIGHUP) stop the children the harness registered (the
// daemon, tcpdump, another receiver: SIGTERM, then SIGKILL after 5 s), have the guard run its
// commands (the veth pair's removal), and then take their usual course: the harness ends by the
// signal. Without it a daemon would outlive the harness that started it, and a veth pair and a
// namespace would stay.
//
// The commands run in a guard process forked when they are given, not in the handler: a handler
// may only make async-signal-safe calls, and a fork from one is not safe in every runtime (under
// TSan the child's first allocation is reported and it never runs the command). The guard waits
// on a socket only the harness writes: 'r' runs the commands, 'q' ends it without, and the
// socket's end (the harness died without a word: SIGKILL, a crash) runs them too. It ignores
// SIGINT, SIGTERM and SIGHUP, which a terminal sends to the whole process group.
//
// The handler is the harness's alone: every child the harness forks drops it before it can get a
// signal (harness::reset_signals_for_exec). A daemon stopped between its fork and its exec once
// ran it, told the guard to remove the work directory, and the harness then died of SIGPIPE
// telling the guard that was gone.
#pragma once

#include <signal.h>

#include <array>
#include <string>
#include <vector>

namespace pandarcap::bench {

class StopOnSignal {
 public:
  StopOnSignal();
  ~StopOnSignal();  // ends the guard without running its commands
  StopOnSignal(const StopOnSignal&) = delete;
  StopOnSignal& operator=(const StopOnSignal&) = delete;

  // Starts a guard with these commands (each argv[0] the program's path; output to /dev/null),
  // run in order; returns its number for run_guarded_now. Up to four guards (the veth pair, the
  // work directory), each run when a signal comes. Throws std::runtime_error when it cannot fork.
  int guard(std::vector<std::vector<std::string>> commands);
  // Has guard `guard` run its commands now and waits for it (a no-op once it has).
  void run_guarded_now(int guard) noexcept;

  // SIGINT, SIGTERM and SIGHUP held off in this thread while it lives (or until release()): a child
  // forked meanwhile is registered (Child) before the handler can look for it, or a signal in
  // between would leave it running. A child's own mask is reset (harness::ChildProcess).
  class Held {
   public:
    Held();
    ~Held();
    Held(const Held&) = delete;
    Held& operator=(const Held&) = delete;
    void release() noexcept;

   private:
    sigset_t old_{};
    bool held_ = true;
  };

  // A child of the harness's, stopped by the handler while this lives (a no-op with no
  // StopOnSignal alive), or until release(): call that once the child is reaped, or a signal
  // would send SIGTERM to its pid, which the system may have given to another process since.
  class Child {
   public:
    explicit Child(int pid);
    ~Child();
    void release() noexcept;
    Child(const Child&) = delete;
    Child& operator=(const Child&) = delete;

   private:
    int slot_ = -1;
  };

 private:
  std::array<struct sigaction, 3> old_{};  // SIGINT, SIGTERM, SIGHUP as they were
  std::array<bool, 3> installed_{};        // the handler put in their place (not ignored)
};

// Runs `argv` (argv[0] the program's path) with its output to /dev/null and waits for it.
void spawn_and_wait(const std::vector<std::string>& args);

}  // namespace pandarcap::bench
