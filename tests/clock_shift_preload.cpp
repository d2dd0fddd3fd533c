// LD_PRELOAD shim for the wall-clock-jump test (tests/test_wall_clock.cpp): moves CLOCK_REALTIME,
// as clock_gettime, gettimeofday and time report it, by the whole seconds written in the file
// named by PANDARCAP_TEST_CLOCK_SHIFT_FILE ("3600", "-7200"), as an administrator or NTP stepping
// the host clock would. Every other clock passes through untouched. The file is read again at most
// every 20 ms, with plain system calls: nothing here allocates or locks.
#include <dlfcn.h>
#include <fcntl.h>
#include <sys/time.h>
#include <time.h>
#include <unistd.h>

#include <atomic>
#include <cstdint>
#include <cstdlib>

namespace {

using ClockGettime = int (*)(clockid_t, timespec*);

ClockGettime real_clock_gettime() {
  static const auto real = reinterpret_cast<ClockGettime>(dlsym(RTLD_NEXT, "clock_gettime"));
  return real;
}

std::atomic<std::int64_t> shift_s{0};
std::atomic<std::int64_t> next_read_ns{0};

std::int64_t current_shift_s() {
  timespec now{};
  real_clock_gettime()(CLOCK_MONOTONIC, &now);
  const std::int64_t now_ns = now.tv_sec * 1'000'000'000LL + now.tv_nsec;
  std::int64_t due = next_read_ns.load(std::memory_order_relaxed);
  if (now_ns >= due &&
      next_read_ns.compare_exchange_strong(due, now_ns + 20'000'000, std::memory_order_relaxed)) {
    if (const char* path = std::getenv("PANDARCAP_TEST_CLOCK_SHIFT_FILE")) {
      const int fd = ::open(path, O_RDONLY | O_CLOEXEC);
      if (fd >= 0) {
        char text[32] = {};
        const ssize_t n = ::read(fd, text, sizeof text - 1);
        ::close(fd);
        if (n > 0) shift_s.store(std::strtoll(text, nullptr, 10), std::memory_order_relaxed);
      }
    }
  }
  return shift_s.load(std::memory_order_relaxed);
}

}  // namespace

extern "C" {

int clock_gettime(clockid_t clock, timespec* out) {
  const int result = real_clock_gettime()(clock, out);
  if (result == 0 && out != nullptr &&
      (clock == CLOCK_REALTIME || clock == CLOCK_REALTIME_COARSE)) {
    out->tv_sec += current_shift_s();
  }
  return result;
}

int gettimeofday(timeval* out, void*) {
  timespec now{};
  const int result = clock_gettime(CLOCK_REALTIME, &now);
  if (result == 0 && out != nullptr) {
    out->tv_sec = now.tv_sec;
    out->tv_usec = static_cast<suseconds_t>(now.tv_nsec / 1000);
  }
  return result;
}

time_t time(time_t* out) {
  timespec now{};
  clock_gettime(CLOCK_REALTIME, &now);
  if (out != nullptr) *out = now.tv_sec;
  return now.tv_sec;
}

}  // extern "C"
