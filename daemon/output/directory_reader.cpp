#include "daemon/output/directory_reader.hpp"

#include <dirent.h>
#include <fcntl.h>
#include <sys/syscall.h>
#include <unistd.h>

namespace pandarcap {
namespace {

// The kernel's directory entry (getdents64).
struct LinuxDirent64 {
  std::uint64_t d_ino;
  std::int64_t d_off;
  unsigned short d_reclen;
  unsigned char d_type;
  char d_name[1];
};

}  // namespace

bool DirectoryReader::open(const char* directory) noexcept {
  close();
  fd_ = ::open(directory, O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  return fd_ >= 0;
}

void DirectoryReader::close() noexcept {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
  filled_ = at_ = 0;
}

bool DirectoryReader::next_entry(std::string_view& name) noexcept {
  while (fd_ >= 0) {
    if (at_ >= filled_) {
      filled_ = ::syscall(SYS_getdents64, fd_, buffer_.data(), buffer_.size());
      at_ = 0;
      if (filled_ <= 0) {  // the end, or the directory went away under us
        close();
        return false;
      }
    }
    const auto* entry = reinterpret_cast<const LinuxDirent64*>(buffer_.data() + at_);
    at_ += entry->d_reclen;
    // A link, a directory, a device: never a file of ours, whatever its name.
    if (entry->d_type != DT_REG && entry->d_type != DT_UNKNOWN) continue;
    name_ = entry->d_name;
    name = std::string_view(entry->d_name);
    return true;
  }
  return false;
}

bool DirectoryReader::stat_entry(File& file) noexcept {
  return ::fstatat(fd_, name_, &file.info, AT_SYMLINK_NOFOLLOW) == 0 && S_ISREG(file.info.st_mode);
}

}  // namespace pandarcap
