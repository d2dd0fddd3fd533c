// Where the benchmark's threads run: two distinct CPUs when the process may use two, otherwise
// both on the only one. (The throughput loops spin, so two threads on one core measure the
// scheduler, not the queue; the stress tests cover one-core correctness.)
#pragma once

#include <pthread.h>
#include <sched.h>

#include <string>
#include <vector>

namespace pandarcap::bench {

inline std::vector<int> allowed_cpus() {
  cpu_set_t set;
  CPU_ZERO(&set);
  std::vector<int> cpus;
  if (sched_getaffinity(0, sizeof(set), &set) != 0) return cpus;
  for (int cpu = 0; cpu < CPU_SETSIZE; ++cpu) {
    if (CPU_ISSET(cpu, &set)) cpus.push_back(cpu);
  }
  return cpus;
}

inline bool pin_this_thread(int cpu) {
  if (cpu < 0) return true;
  cpu_set_t set;
  CPU_ZERO(&set);
  CPU_SET(cpu, &set);
  return pthread_setaffinity_np(pthread_self(), sizeof(set), &set) == 0;
}

struct Placement {
  int producer_cpu = -1;  // -1: not pinned
  int consumer_cpu = -1;
  std::string describe() const {
    if (producer_cpu < 0) return "not pinned";
    if (producer_cpu == consumer_cpu) return "same core (cpu " + std::to_string(producer_cpu) + ")";
    return "separate cores (cpu " + std::to_string(producer_cpu) + " and " +
           std::to_string(consumer_cpu) + ")";
  }
};

inline Placement choose_placement() {
  const std::vector<int> cpus = allowed_cpus();
  if (cpus.empty()) return {};
  if (cpus.size() == 1) return {cpus[0], cpus[0]};
  return {cpus[0], cpus[1]};
}

}  // namespace pandarcap::bench
