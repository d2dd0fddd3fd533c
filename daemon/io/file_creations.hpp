// What creating the daemon's output files costs, in CPU, counted where they are opened
// (OutputFile::try_open): the file system decides it, not the daemon, and it can be most of the
// writer's time. ext4 without a journal passes over every inode of the directory's block group
// freed in the last one to five minutes before it takes one (find_inode_bit's
// check_recently_deleted), reading each one's inode: in a /tmp where a test suite had just removed
// thousands of files, one creation took 450 us of CPU on this project's VM against 15 us
// elsewhere on the same file system, at ten files a second half a percent of a core. The health
// says it (`files_created`, `file_create_cpu_us`) so that a writer made dear by its directory
// can be told from one made dear by its work.
#pragma once

#include <atomic>
#include <cstdint>

namespace pandarcap::io {

struct FileCreations {
  std::atomic<std::uint64_t> files{0};
  std::atomic<std::uint64_t> cpu_ns{0};  // the creating thread's CPU time in open()
};

// The process's count (each creation adds with two relaxed increments: no lock, no allocation).
inline FileCreations& file_creations() noexcept {
  static FileCreations creations;
  return creations;
}

}  // namespace pandarcap::io
