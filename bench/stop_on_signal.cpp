#include "bench/stop_on_signal.hpp"

#include <fcntl.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <cerrno>
#include <memory>

namespace pandarcap::bench {

namespace {

constexpr int kSlots = 16;
std::array<std::atomic<int>, kSlots> g_children{};
std::atomic<bool> g_active{false};

// The commands, owned here so that the handler reads them without allocating.
struct Command {
  std::vector<std::string> args;
  std::vector<char*> argv;
};
std::vector<std::unique_ptr<Command>> g_commands;
std::atomic<int> g_command_count{0};

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

void on_signal(int signal_number) {
  const int saved_errno = errno;  // the interrupted code's, until the signal ends the process
  stop_children();
  const int commands = g_command_count.load();
  for (int i = 0; i < commands; ++i)
    spawn_and_wait(g_commands[static_cast<std::size_t>(i)]->argv.data());
  struct sigaction default_action {};
  default_action.sa_handler = SIG_DFL;
  ::sigaction(signal_number, &default_action, nullptr);
  ::raise(signal_number);  // delivered when the handler returns: the process ends by it
  errno = saved_errno;
}

}  // namespace

void spawn_and_wait(char* const* argv) {
  const pid_t pid = ::fork();
  if (pid == 0) {
    const int null = ::open("/dev/null", O_WRONLY);
    if (null >= 0) {
      ::dup2(null, 1);
      ::dup2(null, 2);
    }
    ::execv(argv[0], argv);
    ::_exit(127);
  }
  if (pid > 0) {
    int status = 0;
    ::waitpid(pid, &status, 0);
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
  g_command_count.store(0);
  g_commands.clear();
}

void StopOnSignal::run_on_signal(std::vector<std::string> argv) {
  auto command = std::make_unique<Command>();
  command->args = std::move(argv);
  for (std::string& a : command->args)
    command->argv.push_back(a.data());
  command->argv.push_back(nullptr);
  // The signals wait while the table grows (a vector that moves its elements is not to be read
  // from a handler meanwhile).
  sigset_t both, old;
  ::sigemptyset(&both);
  ::sigaddset(&both, SIGINT);
  ::sigaddset(&both, SIGTERM);
  ::pthread_sigmask(SIG_BLOCK, &both, &old);
  g_commands.push_back(std::move(command));
  g_command_count.store(static_cast<int>(g_commands.size()));
  ::pthread_sigmask(SIG_SETMASK, &old, nullptr);
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
