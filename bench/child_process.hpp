// Runs pandarcapd (or any binary) in the background, for the integration tests and the
// benchmark harness: start with arguments and extra environment, send signals, wait for exit with
// a deadline, read its log. Plus the waiting primitive used instead of sleeps (poll a condition
// until it holds or a deadline passes) and small loopback UDP helpers.
#pragma once

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace pandarcap::harness {

// In a child between fork and exec: every caught signal back to its default action, then
// nothing blocked. Until exec the child has its parent's handlers, and a signal it gets there
// (the harness stopping it just after the fork) would run the parent's handler in the child:
// the zero-loss harness's told its guard to remove the work directory, as if the harness itself
// had been stopped. Async-signal-safe.
void reset_signals_for_exec() noexcept;

class ChildProcess {
 public:
  // Starts `program args...` with `env` added to the environment; stdout and stderr go to
  // `log_path`.
  ChildProcess(const std::filesystem::path& program, const std::vector<std::string>& args,
               const std::filesystem::path& log_path, const std::vector<std::string>& env = {});
  ~ChildProcess();  // kills (SIGKILL) a process still running
  ChildProcess(const ChildProcess&) = delete;
  ChildProcess& operator=(const ChildProcess&) = delete;

  int pid() const noexcept { return pid_; }
  void signal(int signal_number) const;
  // The exit status, or nullopt if it did not exit within `timeout` (or died from a signal: -sig).
  std::optional<int> wait_exit(std::chrono::milliseconds timeout);
  std::string log() const;
  // Whether its log has `text` in it so far.
  bool logged(std::string_view text) const;

 private:
  int pid_ = -1;
  bool reaped_ = false;
  std::filesystem::path log_path_;
};

// What a /bin/sh command printed on its standard output, and how it ended (pclose's status: 0
// when it exited 0; -1 when it could not be run).
struct ShellResult {
  int status = -1;
  std::string out;
};
ShellResult run_shell(const std::string& command);

// The binary `name` in this executable's directory (the build's bin/, or /usr/bin installed), or
// `name` alone, for PATH to find, when /proc/self/exe cannot be read.
std::filesystem::path beside_this_binary(const std::string& name);

// The whole file as text ("" when it cannot be read): logs, /proc files.
std::string read_file(const std::filesystem::path& path);

// A memory figure from /proc/PID/status, in bytes: `field` is "VmRSS" (resident now), "VmHWM"
// (peak resident), ...; 0 when the process or the field is gone.
std::uint64_t process_memory_bytes(int pid, std::string_view field);

// CPU ticks (utime + stime, sysconf(_SC_CLK_TCK) per second) used so far by each thread of
// process `pid`, summed per thread name (/proc/PID/task/*/stat and comm).
std::map<std::string, std::uint64_t> thread_cpu_ticks(int pid);

// CPU nanoseconds used so far by each thread of process `pid`, summed per thread name: the time
// on a CPU the scheduler accounts exactly (/proc/PID/task/*/schedstat, its first field), not
// ticks sampled at 100 Hz, which see 0.2 % of a core over 10 s as 2 ticks. Where schedstat is
// missing (a kernel without CONFIG_SCHED_INFO), the ticks converted (`*exact` false).
std::map<std::string, std::uint64_t> thread_cpu_ns(int pid, bool* exact = nullptr);

// Polls `condition` every few milliseconds until it returns true (-> true) or `timeout` passes
// (-> false).
bool wait_until(const std::function<bool()>& condition, std::chrono::milliseconds timeout);

// A UDP port on 127.0.0.1 that was free a moment ago.
std::uint16_t free_udp_port();

// Sends `payloads` as UDP datagrams from `source_ip` (any port) to 127.0.0.1:`port`.
void send_udp(const std::string& source_ip, std::uint16_t port,
              const std::vector<std::vector<std::uint8_t>>& payloads);

}  // namespace pandarcap::harness
