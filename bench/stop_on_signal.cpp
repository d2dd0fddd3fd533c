#include "bench/stop_on_signal.hpp"

#include <fcntl.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <cerrno>
#include <stdexcept>

#include "bench/child_process.hpp"

namespace pandarcap::bench {

namespace {

constexpr int kSlots = 16;
std::array<std::atomic<int>, kSlots> g_children{};
std::atomic<bool> g_active{false};
// The guards: each one's pid and the harness's end of its socket + 1 (0 and 0: none, or it has
// been told).
constexpr int kGuards = 4;
std::array<std::atomic<int>, kGuards> g_guard_pid{};
std::array<std::atomic<int>, kGuards> g_guard_socket{};

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

// Tells guard `index` `what` ('r' run, 'q' quit) and waits for it to end. Async-signal-safe.
void tell_guard(int index, char what) noexcept {
  const auto at = static_cast<std::size_t>(index);
  const int socket = g_guard_socket[at].exchange(0) - 1;
  const int pid = g_guard_pid[at].exchange(0);
  if (socket < 0 || pid <= 0) return;
  // MSG_NOSIGNAL: a guard killed from outside must not take the harness with it by SIGPIPE
  // (a pipe would raise it in the middle of the handler's clean-up).
  while (::send(socket, &what, 1, MSG_NOSIGNAL) < 0 && errno == EINTR) {
  }
  ::close(socket);
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
}

void tell_guards(char what) noexcept {
  for (int index = 0; index < kGuards; ++index)
    tell_guard(index, what);
}

// The signals that stop a run: ^C, kill's default, a terminal that hangs up (an ssh session
// dropped during a long run: pandarcapd takes SIGHUP as "rotate" and would run on, orphaned).
constexpr std::array<int, 3> kStopSignals{SIGINT, SIGTERM, SIGHUP};

sigset_t stop_signals() {
  sigset_t set;
  ::sigemptyset(&set);
  for (const int signal_number : kStopSignals)
    ::sigaddset(&set, signal_number);
  return set;
}

void on_signal(int signal_number) {
  const int saved_errno = errno;  // the interrupted code's, until the signal ends the process
  stop_children();
  tell_guards('r');
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
    harness::reset_signals_for_exec();  // a guard's SIG_IGN stays: its commands outlive a ^C
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
  action.sa_mask = stop_signals();  // each holds off the others while the handler cleans up
  static_assert(std::tuple_size_v<decltype(old_)> == kStopSignals.size());
  for (std::size_t i = 0; i < kStopSignals.size(); ++i) {
    // One the harness was started ignoring stays ignored: a background job of a script (`cmd &`
    // ignores SIGINT), nohup (SIGHUP). Its handler would stop a run that was meant to go on.
    ::sigaction(kStopSignals[i], nullptr, &old_[i]);
    if (old_[i].sa_handler == SIG_IGN) continue;
    ::sigaction(kStopSignals[i], &action, nullptr);
    installed_[i] = true;
  }
}

StopOnSignal::~StopOnSignal() {
  for (std::size_t i = 0; i < kStopSignals.size(); ++i) {
    if (installed_[i]) ::sigaction(kStopSignals[i], &old_[i], nullptr);
  }
  g_active.store(false);
  tell_guards('q');
}

int StopOnSignal::guard(std::vector<std::vector<std::string>> commands) {
  int index = 0;
  while (index < kGuards && g_guard_pid[static_cast<std::size_t>(index)].load() != 0)
    ++index;
  if (index == kGuards) throw std::runtime_error("no room for another guard process");
  int ends[2];
  if (::socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, ends) != 0) {
    throw std::runtime_error("cannot make the guard's socket");
  }
  Held held;  // the guard must not run the harness's handler before it ignores the signals
  const pid_t pid = ::fork();
  if (pid < 0) {
    ::close(ends[0]);
    ::close(ends[1]);
    throw std::runtime_error("cannot fork the guard process");
  }
  if (pid == 0) {
    // The guard: outlives a terminal's SIGINT or hang-up to the group, waits for its word or the
    // harness's end.
    for (const int signal_number : kStopSignals)
      ::signal(signal_number, SIG_IGN);
    harness::reset_signals_for_exec();
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
  g_guard_socket[static_cast<std::size_t>(index)].store(ends[1] + 1);
  g_guard_pid[static_cast<std::size_t>(index)].store(pid);
  return index;
}

void StopOnSignal::run_guarded_now(int guard) noexcept {
  if (guard >= 0 && guard < kGuards) tell_guard(guard, 'r');
}

StopOnSignal::Held::Held() {
  const sigset_t stopping = stop_signals();
  ::pthread_sigmask(SIG_BLOCK, &stopping, &old_);
}

StopOnSignal::Held::~Held() {
  release();
}

void StopOnSignal::Held::release() noexcept {
  if (!held_) return;
  held_ = false;
  ::pthread_sigmask(SIG_SETMASK, &old_, nullptr);  // a signal that came meanwhile arrives now
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
  release();
}

void StopOnSignal::Child::release() noexcept {
  if (slot_ >= 0) g_children[static_cast<std::size_t>(slot_)].store(0);
  slot_ = -1;
}

}  // namespace pandarcap::bench
