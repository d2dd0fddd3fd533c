// What a zero-loss run leaves behind when SIGINT or SIGTERM stops it: nothing. While a
// StopOnSignal lives, those signals stop the children the harness registered (the daemon, tcpdump,
// another receiver: SIGTERM, then SIGKILL after 5 s), run the commands it was given (the veth
// pair's removal), and then take their usual course: the harness ends by the signal. Without it a
// daemon would outlive the harness that started it, and a veth pair and a namespace would stay.
//
// The handler may only use async-signal-safe calls (kill, waitpid, nanosleep, fork, execv,
// sigaction, raise), so children are kept in a fixed table of atomics and commands as prepared
// argument vectors. One StopOnSignal at a time.
#pragma once

#include <signal.h>

#include <string>
#include <vector>

namespace pandarcap::bench {

class StopOnSignal {
 public:
  StopOnSignal();
  ~StopOnSignal();
  StopOnSignal(const StopOnSignal&) = delete;
  StopOnSignal& operator=(const StopOnSignal&) = delete;

  // `argv[0]` is the program's path; run (and waited for) by the handler, in the order given,
  // after the children have stopped. Output goes to /dev/null.
  void run_on_signal(std::vector<std::string> argv);

  // A child of the harness's, stopped by the handler while this lives (a no-op with no
  // StopOnSignal alive).
  class Child {
   public:
    explicit Child(int pid);
    ~Child();
    Child(const Child&) = delete;
    Child& operator=(const Child&) = delete;

   private:
    int slot_ = -1;
  };

 private:
  struct sigaction old_int_ {};
  struct sigaction old_term_ {};
};

// Runs `argv` (argv[0] the program's path) with its output to /dev/null and waits for it.
// Async-signal-safe, given prepared arguments.
void spawn_and_wait(char* const* argv);

}  // namespace pandarcap::bench
