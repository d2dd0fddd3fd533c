// The seam between the daemon's files and the kernel: the system calls that write and close
// files, replaceable by tests.
//
// A full disk, an interrupted write or a write that takes only part of its bytes are rare on a
// test machine, yet each must be counted and survived. The tests put their own functions here
// (ScopedFileSyscalls) and so reach every one of those paths without mounting a tmpfs; the
// daemon never changes them. The table is read once per call with a relaxed atomic load: no
// measurable cost beside the system call itself.
#pragma once

#include <sys/types.h>

#include <atomic>
#include <cstddef>

namespace pandarcap::io {

struct FileSyscalls {
  ssize_t (*write)(int fd, const void* data, std::size_t size);
  int (*ftruncate)(int fd, off_t size);
  int (*close)(int fd);
  // What makes a file's data durable (daemon/output/file_finisher): a disk that fails here (EIO)
  // lost what the page cache held, and the file must not get its final name.
  int (*fdatasync)(int fd);
};

// The kernel's own calls.
FileSyscalls real_file_syscalls() noexcept;
// The calls OutputFile uses now.
const FileSyscalls& file_syscalls() noexcept;

// Test-only: replaces the calls for its lifetime, then puts the previous ones back. Not for use
// while another thread writes files (the tests use it on their own thread, daemon not running).
class ScopedFileSyscalls {
 public:
  explicit ScopedFileSyscalls(const FileSyscalls& calls) noexcept;
  ~ScopedFileSyscalls();
  ScopedFileSyscalls(const ScopedFileSyscalls&) = delete;
  ScopedFileSyscalls& operator=(const ScopedFileSyscalls&) = delete;

 private:
  FileSyscalls calls_;
  const FileSyscalls* previous_;
};

}  // namespace pandarcap::io
