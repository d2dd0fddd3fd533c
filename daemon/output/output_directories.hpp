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
#include <string_view>
#include <vector>

#include "daemon/io/file_output.hpp"
#include "daemon/io/unique_fd.hpp"
#include "daemon/output/writer_options.hpp"

namespace pandarcap {

// The file a directory is proven writable with (created and removed at once): at start-up, and
// while the health directory fails, every second (health_publisher.hpp). Hidden, and named as
// the temporaries a start removes.
inline constexpr std::string_view kProbeFileName = ".pandarcapd-probe.tmp";

// One line per problem ("frames directory '/x/frames': '/x' is not a directory"); empty: fine.
std::vector<std::string> output_problems(const WriterOptions& options);

// The free space on each output's file system against what the start needs to begin writing:
// kOutputFloorBytes + kHealthReserveBytes (health_room.hpp). One line per file system in
// `report` ("frames directory '/x/frames': 812 MiB free, 40 MiB needed"); returns the problems
// (the same line, for each file system short of it). `--check-config` prints both; the start
// refuses with the problems (exit 73).
std::vector<std::string> space_problems(const WriterOptions& options,
                                        std::vector<std::string>& report);

// The free-space floor on each output's file system, one line each for `--check-config`: the
// configured one, or that it is raised to the health files' room plus 2 s of writing
// (space_floor.hpp).
std::vector<std::string> floor_report(const WriterOptions& options);

// Where the health files would go while their own directory cannot be written: each of
// health_fallback_dirs tried in order, up to the first one this user can write ("'DIR' (made when
// first needed)" / "'DIR' cannot be used: WHY"). For --check-config: a warning, not a refusal
// (the capture does not need it).
std::vector<std::string> health_fallback_report(const WriterOptions& options);

// A directory of ours removed while the daemon runs (a USB disk pulled, a clean-up script): made
// again and said in the log. True when it was missing and exists now; false when it was there
// (the failure was something else) or cannot be made.
bool make_again_if_removed(const std::filesystem::path& directory) noexcept;

// Opens `file` at `path`, which is in `directory`: when the open fails because the directory
// was removed, it is made again and the open tried once more. Returns the failure (the writer's
// loop: nothing thrown, nothing allocated unless the directory must be made again).
io::IoError open_in_directory(OutputFile& file, std::string_view path, OutputFile::Mode mode,
                              const std::filesystem::path& directory);

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
