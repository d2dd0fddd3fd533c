// Fuzz target: finishing an MCAP file a killed run left (daemon/mcap/mcap_recovery.hpp), which
// parses every record of an untrusted file: chunk, attachment and index lengths, zstd frames,
// message records inside chunks. The input is the whole .part file. Any input is either left
// alone (not ours), or cut and finished; finishing what was finished again keeps the same
// messages, the same bytes before the tail and the same length (the tail is rebuilt, never
// grown), so a recovered file is a fixed point.
#include <fcntl.h>
#include <unistd.h>

#include <cstdint>
#include <cstdlib>
#include <string>
#include <system_error>

#include "daemon/mcap/mcap_recovery.hpp"

using namespace pandarcap;

namespace {

std::uint64_t file_size(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) std::abort();
  const off_t size = ::lseek(fd, 0, SEEK_END);
  ::close(fd);
  return static_cast<std::uint64_t>(size);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  // A real file: the recovery opens by name with O_NOFOLLOW (a /proc/self/fd link is refused).
  static const std::string path = "/tmp/fuzz-mcap-" + std::to_string(::getpid()) + ".mcap.part";
  const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
  if (fd < 0 || ::pwrite(fd, data, size, 0) != static_cast<ssize_t>(size)) std::abort();
  ::close(fd);
  McapRecovery first;
  try {
    first = finish_interrupted_mcap(path);
  } catch (const std::system_error&) {
    std::abort();  // a regular file we can read and write: I/O cannot fail
  }
  // What was examined adds up to the file (a file that is not ours is not examined).
  if (first.ours && (first.kept_bytes > size || first.kept_bytes + first.cut_bytes != size)) {
    std::abort();
  }
  if (!first.ours || first.messages == 0) {
    if (file_size(path) != size) std::abort();  // left as it was
    return 0;
  }
  const std::uint64_t finished = file_size(path);
  const McapRecovery again = finish_interrupted_mcap(path);
  if (!again.ours || again.messages != first.messages || again.kept_bytes != first.kept_bytes ||
      file_size(path) != finished) {
    std::abort();
  }
  return 0;
}
