#include "bench/child_process.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <thread>

#include "core/ipv4.hpp"

extern char** environ;

namespace pandarcap::harness {

void reset_signals_for_exec() noexcept {
  for (int signal_number = 1; signal_number < NSIG; ++signal_number) {
    struct sigaction current {};
    if (::sigaction(signal_number, nullptr, &current) != 0) continue;  // SIGKILL, SIGSTOP, RT
    if (current.sa_handler == SIG_DFL || current.sa_handler == SIG_IGN) continue;
    struct sigaction default_action {};
    default_action.sa_handler = SIG_DFL;
    ::sigaction(signal_number, &default_action, nullptr);
  }
  sigset_t none;
  sigemptyset(&none);
  ::sigprocmask(SIG_SETMASK, &none, nullptr);
}

ChildProcess::ChildProcess(const std::filesystem::path& program,
                           const std::vector<std::string>& args,
                           const std::filesystem::path& log_path,
                           const std::vector<std::string>& env)
    : log_path_(log_path) {
  std::vector<std::string> argv_strings{program.string()};
  argv_strings.insert(argv_strings.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& s : argv_strings)
    argv.push_back(s.data());
  argv.push_back(nullptr);
  std::vector<std::string> env_strings;
  for (char** e = environ; *e != nullptr; ++e)
    env_strings.emplace_back(*e);
  env_strings.insert(env_strings.end(), env.begin(), env.end());
  std::vector<char*> envp;
  for (std::string& s : env_strings)
    envp.push_back(s.data());
  envp.push_back(nullptr);

  pid_ = ::fork();
  if (pid_ < 0) throw std::runtime_error("fork failed");
  if (pid_ == 0) {
    const int fd = ::open(log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd >= 0) {
      ::dup2(fd, 1);
      ::dup2(fd, 2);
    }
    // Signals the test runner blocks must not stay blocked in the daemon.
    reset_signals_for_exec();
    ::execve(argv[0], argv.data(), envp.data());
    ::_exit(127);
  }
}

ChildProcess::~ChildProcess() {
  if (pid_ > 0 && !reaped_) {
    ::kill(pid_, SIGKILL);
    ::waitpid(pid_, nullptr, 0);
  }
}

void ChildProcess::signal(int signal_number) const {
  ::kill(pid_, signal_number);
}

std::optional<int> ChildProcess::wait_exit(std::chrono::milliseconds timeout) {
  if (reaped_) return std::nullopt;
  std::optional<int> result;
  wait_until(
      [&] {
        int status = 0;
        const pid_t r = ::waitpid(pid_, &status, WNOHANG);
        if (r != pid_) return false;
        reaped_ = true;
        result = WIFEXITED(status) ? WEXITSTATUS(status) : -WTERMSIG(status);
        return true;
      },
      timeout);
  return result;
}

std::string ChildProcess::log() const {
  return read_file(log_path_);
}

bool ChildProcess::logged(std::string_view text) const {
  return log().find(text) != std::string::npos;
}

std::filesystem::path beside_this_binary(const std::string& name) {
  std::error_code ec;
  const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe", ec);
  return ec ? std::filesystem::path(name) : self.parent_path() / name;
}

std::string read_file(const std::filesystem::path& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

std::uint64_t process_memory_bytes(int pid, std::string_view field) {
  std::istringstream status(read_file("/proc/" + std::to_string(pid) + "/status"));
  for (std::string line; std::getline(status, line);) {
    // "VmRSS:	   36412 kB"
    if (line.size() > field.size() && line.compare(0, field.size(), field) == 0 &&
        line[field.size()] == ':') {
      return std::stoull(line.substr(field.size() + 1)) * 1024;
    }
  }
  return 0;
}

std::map<std::string, std::uint64_t> thread_cpu_ticks(int pid) {
  std::map<std::string, std::uint64_t> ticks;
  std::error_code ec;
  const auto tasks = std::filesystem::path("/proc") / std::to_string(pid) / "task";
  for (const auto& task : std::filesystem::directory_iterator(tasks, ec)) {
    const std::string stat = read_file(task.path() / "stat");
    const auto close = stat.rfind(')');  // the name may hold spaces; fields follow the last ')'
    if (close == std::string::npos || close + 2 > stat.size()) continue;
    std::istringstream fields(stat.substr(close + 2));
    std::string field;
    std::uint64_t utime = 0, stime = 0;
    for (int i = 3; i <= 15 && fields >> field; ++i) {
      if (i == 14) utime = std::stoull(field);
      if (i == 15) stime = std::stoull(field);
    }
    std::string name = read_file(task.path() / "comm");
    while (!name.empty() && (name.back() == '\n' || name.back() == ' '))
      name.pop_back();
    ticks[name] += utime + stime;
  }
  return ticks;
}

std::map<std::string, std::uint64_t> thread_cpu_ns(int pid, bool* exact) {
  std::map<std::string, std::uint64_t> ns;
  bool all_exact = true;
  std::error_code ec;
  const auto tasks = std::filesystem::path("/proc") / std::to_string(pid) / "task";
  for (const auto& task : std::filesystem::directory_iterator(tasks, ec)) {
    std::istringstream schedstat(read_file(task.path() / "schedstat"));
    std::uint64_t on_cpu = 0;
    std::string name = read_file(task.path() / "comm");
    while (!name.empty() && (name.back() == '\n' || name.back() == ' '))
      name.pop_back();
    if (schedstat >> on_cpu) {
      ns[name] += on_cpu;
      continue;
    }
    all_exact = false;
    const std::string stat = read_file(task.path() / "stat");
    const auto close = stat.rfind(')');
    if (close == std::string::npos || close + 2 > stat.size()) continue;
    std::istringstream fields(stat.substr(close + 2));
    std::string field;
    std::uint64_t ticks = 0;
    for (int i = 3; i <= 15 && fields >> field; ++i) {
      if (i == 14 || i == 15) ticks += std::stoull(field);
    }
    ns[name] += ticks * 1'000'000'000ULL / static_cast<std::uint64_t>(::sysconf(_SC_CLK_TCK));
  }
  if (exact != nullptr) *exact = all_exact;
  return ns;
}

bool wait_until(const std::function<bool()>& condition, std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  for (;;) {
    if (condition()) return true;
    if (std::chrono::steady_clock::now() >= deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));  // polling period, not a sync
  }
}

ShellResult run_shell(const std::string& command) {
  ShellResult result;
  FILE* p = ::popen(command.c_str(), "r");
  if (p == nullptr) return result;
  char buffer[512];
  while (std::fgets(buffer, sizeof buffer, p) != nullptr)
    result.out += buffer;
  result.status = ::pclose(p);
  return result;
}

std::uint16_t free_udp_port() {
  const int fd = ::socket(AF_INET, SOCK_DGRAM, 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ::bind(fd, reinterpret_cast<sockaddr*>(&address), sizeof address);
  socklen_t length = sizeof address;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&address), &length);
  ::close(fd);
  return ntohs(address.sin_port);
}

void send_udp(const std::string& source_ip, std::uint16_t port,
              const std::vector<std::vector<std::uint8_t>>& payloads) {
  const int fd = ::socket(AF_INET, SOCK_DGRAM, 0);
  const sockaddr_in source = ipv4_endpoint(source_ip, 0, "sender");
  if (::bind(fd, reinterpret_cast<const sockaddr*>(&source), sizeof source) != 0) {
    ::close(fd);
    throw std::runtime_error("cannot bind a sender to " + source_ip);
  }
  sockaddr_in destination{};
  destination.sin_family = AF_INET;
  destination.sin_port = htons(port);
  destination.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  for (const auto& payload : payloads) {
    while (::sendto(fd, payload.data(), payload.size(), 0,
                    reinterpret_cast<sockaddr*>(&destination), sizeof destination) < 0 &&
           (errno == ENOBUFS || errno == EAGAIN)) {
    }
  }
  ::close(fd);
}

}  // namespace pandarcap::harness
