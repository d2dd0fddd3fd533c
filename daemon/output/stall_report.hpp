// The health of a writer that does not come back from its disk (a file system that hangs rather
// than fails: frozen, a dead NFS server, a USB disk that stopped answering), written by the main
// thread, which the disk cannot hold: the writer's own fallback (health_publisher.hpp) needs the
// writer, and a writer stuck in a system call writes nothing, so its health would go stale.
//
// While the writer's heartbeat stands (the main thread sees it: daemon/pandarcapd_main.cpp), a
// small .prom and a JSON line go to the first health.fallback_directory that takes them, under the
// names the writer's own fallback uses: state degraded, "writer stalled for N s: its disk does not
// answer (...)", pandarcap_writer_stalled_seconds. When the writer beats again its own health
// takes over, and the report's .prom is removed unless the writer has replaced it since. Not on
// the packet path; allocates (a report a second, only while stalled).
#pragma once

#include <sys/types.h>

#include <cstdint>
#include <string>

#include "daemon/output/writer_options.hpp"

namespace pandarcap {

class StalledWriterReport {
 public:
  explicit StalledWriterReport(const WriterOptions& options);

  // The writer has not beaten for `stalled_seconds`: the report (again), at the wall time
  // `unix_ns`. Never throws; where no fallback directory takes it, that is logged.
  void write(double stalled_seconds, std::int64_t unix_ns) noexcept;
  // The writer beats again: the report's .prom removed, if still the one written here.
  void clear() noexcept;
  bool active() const noexcept { return written_inode_ != 0; }

 private:
  const WriterOptions& options_;
  std::string prom_path_;  // of the fallback directory that took the last report
  ino_t written_inode_ = 0;
  bool logged_ = false;
};

}  // namespace pandarcap
