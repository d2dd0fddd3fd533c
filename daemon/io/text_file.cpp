#include "daemon/io/text_file.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>

namespace pandarcap {

TextFile read_text_file(const std::string& path, std::size_t max_bytes) {
  TextFile file;
  // O_NONBLOCK: opening a FIFO with no writer must not wait for one (and a signal could not end
  // the wait: the daemon blocks its signals). Whatever is not a regular file is refused before
  // anything is read from it.
  const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) {
    file.status = TextFile::Status::kCannotOpen;
    file.error_number = errno;
    return file;
  }
  struct stat info {};
  if (::fstat(fd, &info) != 0 || !S_ISREG(info.st_mode)) {
    file.status = TextFile::Status::kNotRegular;
    ::close(fd);
    return file;
  }
  // One byte more than allowed: reading it means the file is too large.
  file.text.assign(max_bytes + 1, '\0');
  std::size_t got = 0;
  while (got < file.text.size()) {
    const ssize_t n = ::read(fd, file.text.data() + got, file.text.size() - got);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      file.status = TextFile::Status::kCannotRead;
      file.error_number = errno;
      file.text.clear();
      ::close(fd);
      return file;
    }
    if (n == 0) break;
    got += static_cast<std::size_t>(n);
  }
  ::close(fd);
  file.text.resize(got);
  if (file.text.size() > max_bytes) {
    file.status = TextFile::Status::kTooLarge;
    file.text.clear();
  }
  return file;
}

}  // namespace pandarcap
