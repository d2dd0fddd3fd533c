// LD_PRELOAD shim for the thread census (tests/support/thread_census.cpp): every pthread_create
// in a process that has it preloaded appends one line, the program's name, to the file named by
// PANDARCAP_THREAD_CENSUS, then creates the thread as asked. The release test job preloads it
// into the test binary, and so into every binary a test starts (children inherit LD_PRELOAD),
// to learn which tests start threads: the ThreadSanitizer job runs exactly those.
//
// One write(2) of a short line to a file opened with O_APPEND: lines from several processes do
// not interleave. Nothing here allocates or locks.
#include <dlfcn.h>
#include <fcntl.h>
#include <pthread.h>
#include <unistd.h>

#include <cstdlib>
#include <cstring>

namespace {

using PthreadCreate = int (*)(pthread_t*, const pthread_attr_t*, void* (*)(void*), void*);

void note_thread(const char* census) {
  char exe[256];
  const ssize_t n = ::readlink("/proc/self/exe", exe, sizeof exe - 1);
  if (n <= 0) return;
  exe[n] = '\0';
  const char* slash = std::strrchr(exe, '/');
  char line[256];
  const std::size_t name_length = std::strlen(slash != nullptr ? slash + 1 : exe);
  if (name_length + 1 >= sizeof line) return;
  std::memcpy(line, slash != nullptr ? slash + 1 : exe, name_length);
  line[name_length] = '\n';
  const int fd = ::open(census, O_WRONLY | O_APPEND | O_CLOEXEC);
  if (fd < 0) return;
  [[maybe_unused]] const ssize_t written = ::write(fd, line, name_length + 1);
  ::close(fd);
}

}  // namespace

extern "C" int pthread_create(pthread_t* thread, const pthread_attr_t* attributes,
                              void* (*start)(void*), void* argument) {
  static const auto real = reinterpret_cast<PthreadCreate>(dlsym(RTLD_NEXT, "pthread_create"));
  if (const char* census = std::getenv("PANDARCAP_THREAD_CENSUS")) note_thread(census);
  return real(thread, attributes, start, argument);
}
