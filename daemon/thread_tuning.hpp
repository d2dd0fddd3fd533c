// Optional placement of the daemon's threads for a dedicated vehicle PC: pin a thread to a CPU,
// give it a SCHED_FIFO real-time priority, lock all memory in RAM (mlockall).
//
// All of it is best effort by design. The limits that say no (a CPU outside the service's
// CPUAffinity=, RLIMIT_RTPRIO / LimitRTPRIO=, RLIMIT_MEMLOCK / LimitMEMLOCK=, a container
// without CAP_SYS_NICE) are the operator's choice, not a fault of the capture: each request logs
// what it got, or what refused it and the limit to raise, and the daemon carries on.
#pragma once

#include <string>

namespace pandarcap {

// What a thread asks for; cpu < 0 = leave the affinity alone, priority 0 = normal scheduling.
struct ThreadPlacement {
  int cpu = -1;
  int priority = 0;  // 1..99: SCHED_FIFO at this priority
};

// Applies `placement` to the calling thread and logs the outcome under `thread_label`
// ("receive", "decode", "writer"). Returns true when everything asked for was granted.
bool place_this_thread(const char* thread_label, const ThreadPlacement& placement);

// mlockall(MCL_CURRENT), logged the same way. Called once every thread has started, so the
// fixed memory and the thread stacks are all resident. Not MCL_FUTURE: under a tight
// RLIMIT_MEMLOCK it would make a later mapping (a thread stack, a log buffer) fail outright, and
// the hot path maps nothing new after start-up anyway.
bool lock_all_memory();

// "0-1,4": the CPUs this process may run on, for the messages.
std::string allowed_cpus_text();

}  // namespace pandarcap
