// The output directories, checked and claimed before the daemon writes anything.
//
// output_problems() is what `pandarcapd --check-config` adds to the configuration check: every
// directory the writer would create or write to (frames/, raw/, the health directory, the
// textfile directory of the .prom file) must exist as a writable directory or be creatable by
// the user running the check, without creating anything. The start then makes the same promise
// true (Writer::prepare), so a configuration --check-config approves is not refused at start for
// its outputs.
//
// OutputDirectoryLock keeps two daemons out of one output directory: each would number, retain
// and "recover" the other's files. An exclusive flock on OUTPUT-DIR/pandarcapd.lock is held for
// the process's life (the kernel releases it when the process dies, SIGKILL included, so a crash
// never leaves a stale lock); the file holds the holder's pid for the message the second one
// prints.
#pragma once

#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

#include "daemon/io/unique_fd.hpp"
#include "daemon/output/writer.hpp"

namespace pandarcap {

// One line per problem ("frames directory '/x/frames': '/x' is not a directory"); empty: fine.
std::vector<std::string> output_problems(const WriterOptions& options);

class OutputDirectoryBusy : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class OutputDirectoryLock {
 public:
  // Creates `directory` if needed and takes the lock. Throws OutputDirectoryBusy when another
  // process holds it, std::system_error when the lock file cannot be made.
  explicit OutputDirectoryLock(const std::filesystem::path& directory);
  OutputDirectoryLock(const OutputDirectoryLock&) = delete;
  OutputDirectoryLock& operator=(const OutputDirectoryLock&) = delete;

 private:
  io::UniqueFd fd_;  // closing it releases the lock
};

}  // namespace pandarcap
