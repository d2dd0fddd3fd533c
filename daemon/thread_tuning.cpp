#include "daemon/thread_tuning.hpp"

#include <fmt/format.h>
#include <pthread.h>
#include <sched.h>
#include <spdlog/spdlog.h>
#include <sys/mman.h>
#include <sys/resource.h>

#include <cerrno>
#include <cstring>

namespace pandarcap {
namespace {

std::string limit_text(int resource) {
  rlimit limit{};
  if (getrlimit(resource, &limit) != 0) return "unknown";
  if (limit.rlim_cur == RLIM_INFINITY) return "unlimited";
  return fmt::format("{}", limit.rlim_cur);
}

}  // namespace

std::string allowed_cpus_text() {
  cpu_set_t set;
  CPU_ZERO(&set);
  if (sched_getaffinity(0, sizeof set, &set) != 0) return "unknown";
  std::string text;
  for (int cpu = 0; cpu < CPU_SETSIZE; ++cpu) {
    if (!CPU_ISSET(cpu, &set)) continue;
    int last = cpu;
    while (last + 1 < CPU_SETSIZE && CPU_ISSET(last + 1, &set))
      ++last;
    text += text.empty() ? "" : ",";
    text += last == cpu ? fmt::format("{}", cpu) : fmt::format("{}-{}", cpu, last);
    cpu = last;
  }
  return text;
}

bool place_this_thread(const char* thread_label, const ThreadPlacement& placement) {
  bool granted = true;
  if (placement.cpu >= 0) {
    cpu_set_t set;
    CPU_ZERO(&set);
    int error = EINVAL;
    if (placement.cpu < CPU_SETSIZE) {
      CPU_SET(placement.cpu, &set);
      error = pthread_setaffinity_np(pthread_self(), sizeof set, &set);
    }
    if (error == 0) {
      spdlog::info("{} thread: pinned to CPU {}", thread_label, placement.cpu);
    } else {
      // EINVAL: the CPU is offline, absent, or outside the cpuset/CPUAffinity= of the service.
      granted = false;
      spdlog::warn(
          "{} thread: cannot pin to CPU {} ({}; this process may run on CPUs {}); "
          "running unpinned",
          thread_label, placement.cpu, std::strerror(error), allowed_cpus_text());
    }
  }
  if (placement.priority > 0) {
    sched_param param{};
    param.sched_priority = placement.priority;
    const int error = pthread_setschedparam(pthread_self(), SCHED_FIFO, &param);
    if (error == 0) {
      spdlog::info("{} thread: SCHED_FIFO priority {}", thread_label, placement.priority);
    } else {
      granted = false;
      spdlog::warn(
          "{} thread: SCHED_FIFO priority {} refused ({}; RLIMIT_RTPRIO is {}: raise "
          "it with LimitRTPRIO= in the unit, and RestrictRealtime= must be off); "
          "running with normal scheduling",
          thread_label, placement.priority, std::strerror(error), limit_text(RLIMIT_RTPRIO));
    }
  }
  return granted;
}

bool lock_all_memory() {
  if (mlockall(MCL_CURRENT) == 0) {
    spdlog::info("memory: locked in RAM (mlockall); RLIMIT_MEMLOCK is {}",
                 limit_text(RLIMIT_MEMLOCK));
    return true;
  }
  const int error = errno;
  spdlog::warn(
      "memory: mlockall refused ({}; RLIMIT_MEMLOCK is {} bytes: raise it with "
      "LimitMEMLOCK= in the unit); memory stays pageable",
      std::strerror(error), limit_text(RLIMIT_MEMLOCK));
  return false;
}

}  // namespace pandarcap
