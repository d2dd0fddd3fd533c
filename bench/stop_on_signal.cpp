#include "bench/stop_on_signal.hpp"

#include <fcntl.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <cerrno>
#include <stdexcept>

namespace pandarcap::bench {

namespace {

constexpr int kSlots = 16;
std::array<std::atomic<int>, kSlots> g_children{};
std::atomic<bool> g_active{false};
// The guard: its pid and the pipe's write end (0 and -1: none, or it has been told).
std::atomic<int> g_guard_pid{0};
std::atomic<int> g_guard_pipe{-1};

void stop_children() {
  for (auto& slot : g_children) {
    const int pid = slot.load();
    if (pid > 0) ::kill(pid, SIGTERM);
  }
  // Up to 5 s for them to finish (a daemon closes its files), then SIGKILL.
  for (int waited_ms = 0;; waited_ms += 10) {
    bool running = false;
    for (auto& slot : g_children) {
      const int pid = slot.load();
      if (pid <= 0) continue;
      int status = 0;
      if (::waitpid(pid, &status, WNOHANG) == 0) {
        running = true;
        if (waited_ms >= 5000) ::kill(pid, SIGKILL);
      } else {
        slot.store(0);
      }
    }
    if (!running) return;
    const timespec step{0, 10'000'000};
    ::nanosleep(&step, nullptr);
  }
}

// Tells the guard `what` ('r' run, 'q' quit) and waits for it to end. Async-signal-safe.
void tell_guard(char what) noexcept {
  const int pipe = g_guard_pipe.exchange(-1);
  const int pid = g_guard_pid.exchange(0);
  if (pipe < 0 || pid <= 0) return;
  while (::write(pipe, &what, 1) < 0 && errno == EINTR) {
  }
  ::close(pipe);
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
}

void on_signal(int signal_number) {
  const int saved_errno = errno;  // the interrupted code's, until the signal ends the process
  stop_children();
  tell_guard('r');
  struct sigaction default_action {};
  default_action.sa_handler = SIG_DFL;
  ::sigaction(signal_number, &default_action, nullptr);
  ::raise(signal_number);  // delivered when the handler returns: the process ends by it
  errno = saved_errno;
}

}  // namespace

void spawn_and_wait(const std::vector<std::string>& args) {
  std::vector<char*> argv;
  for (const std::string& a : args)
    argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  const pid_t pid = ::fork();
  if (pid == 0) {
    const int null = ::open("/dev/null", O_WRONLY);
    if (null >= 0) {
      ::dup2(null, 1);
      ::dup2(null, 2);
    }
    ::execv(argv[0], argv.data());
    ::_exit(127);
  }
  if (pid > 0) {
    int status = 0;
    while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
    }
  }
}

StopOnSignal::StopOnSignal() {
  g_active.store(true);
  struct sigaction action {};
  action.sa_handler = on_signal;
  ::sigemptyset(&action.sa_mask);
  // Either signal holds off the other while the handler cleans up.
  ::sigaddset(&action.sa_mask, SIGINT);
  ::sigaddset(&action.sa_mask, SIGTERM);
  ::sigaction(SIGINT, &action, &old_int_);
  ::sigaction(SIGTERM, &action, &old_term_);
}

StopOnSignal::~StopOnSignal() {
  ::sigaction(SIGINT, &old_int_, nullptr);
  ::sigaction(SIGTERM, &old_term_, nullptr);
  g_active.store(false);
  tell_guard('q');
}

void StopOnSignal::guard(std::vector<std::vector<std::string>> commands) {
  int ends[2];
  if (::pipe2(ends, O_CLOEXEC) != 0) throw std::runtime_error("cannot make the guard's pipe");
  const pid_t pid = ::fork();
  if (pid < 0) {
    ::close(ends[0]);
    ::close(ends[1]);
    throw std::runtime_error("cannot fork the guard process");
  }
  if (pid == 0) {
    // The guard: outlives a terminal's SIGINT to the group, waits for its word or the harness's
    // end.
    ::signal(SIGINT, SIG_IGN);
    ::signal(SIGTERM, SIG_IGN);
    ::close(ends[1]);
    char what = 0;
    ssize_t n = 0;
    while ((n = ::read(ends[0], &what, 1)) < 0 && errno == EINTR) {
    }
    if (n <= 0 || what == 'r') {
      for (const auto& command : commands)
        spawn_and_wait(command);
    }
    ::_exit(0);
  }
  ::close(ends[0]);
  g_guard_pipe.store(ends[1]);
  g_guard_pid.store(pid);
}

void StopOnSignal::run_guarded_now() noexcept {
  tell_guard('r');
}

StopOnSignal::Child::Child(int pid) {
  if (!g_active.load()) return;
  for (int i = 0; i < kSlots; ++i) {
    int empty = 0;
    if (g_children[static_cast<std::size_t>(i)].compare_exchange_strong(empty, pid)) {
      slot_ = i;
      return;
    }
  }
}

StopOnSignal::Child::~Child() {
  if (slot_ >= 0) g_children[static_cast<std::size_t>(slot_)].store(0);
}

}  // namespace pandarcap::bench
