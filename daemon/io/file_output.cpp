#include "daemon/io/file_output.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <stdio.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <ctime>

#include "daemon/io/errors.hpp"
#include "daemon/io/file_creations.hpp"
#include "daemon/io/syscalls.hpp"

namespace pandarcap {

using io::throw_errno;

namespace {

std::uint64_t thread_cpu_ns() noexcept {
  timespec t{};
  ::clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<std::uint64_t>(t.tv_sec) * 1'000'000'000u +
         static_cast<std::uint64_t>(t.tv_nsec);
}

// The synced file `fd`'s whole pages dropped from the page cache (AfterSync::kDropCached).
void drop_cached_pages(int fd) noexcept {
  // Only once synced: the kernel drops clean pages only, so before the sync this would drop next
  // to nothing. The file's last page, if partly filled, stays: a recording still being written
  // appends to it next, which would otherwise read it back from the disk in the writer's loop.
  // Where the pages are the file (tmpfs) they stay: nothing is lost either way.
  struct stat info {};
  if (::fstat(fd, &info) != 0 || info.st_size <= 0) return;
  const auto page = static_cast<off_t>(::sysconf(_SC_PAGESIZE));
  const off_t whole = info.st_size / page * page;
  if (whole > 0) (void)::posix_fadvise(fd, 0, whole, POSIX_FADV_DONTNEED);
}

}  // namespace

io::IoError OutputFile::try_open(std::string_view path, Mode mode) {
  const bool creating = mode != Mode::kAppend;
  const std::uint64_t cpu_before = creating ? thread_cpu_ns() : 0;
  io::IoError error = open_file(path, mode);
  if (creating && !error) {
    io::FileCreations& created = io::file_creations();
    created.files.fetch_add(1, std::memory_order_relaxed);
    created.cpu_ns.fetch_add(thread_cpu_ns() - cpu_before, std::memory_order_relaxed);
  }
  return error;
}

io::IoError OutputFile::open_file(std::string_view path, Mode mode) {
  if (fd_ >= 0) io::file_syscalls().close(fd_);
  fd_ = -1;
  size_ = 0;
  direct_ = false;
  path_.assign(path);
  const int flags = O_WRONLY | O_CREAT | O_CLOEXEC | (mode == Mode::kAppend ? O_APPEND : O_TRUNC);
  if (mode == Mode::kCreateDirect) {
    do {
      fd_ = ::open(path_.c_str(), flags | O_DIRECT, 0644);
    } while (fd_ < 0 && errno == EINTR);
    direct_ = fd_ >= 0;
    // EINVAL: the file system has no O_DIRECT (tmpfs before Linux 6.6, some FUSE): the page
    // cache it is.
    if (fd_ < 0 && errno != EINVAL) return {errno, "cannot open", path_};
  }
  while (fd_ < 0) {
    fd_ = ::open(path_.c_str(), flags, 0644);
    if (fd_ < 0 && errno != EINTR) return {errno, "cannot open", path_};
  }
  if (mode == Mode::kAppend) {
    const off_t end = ::lseek(fd_, 0, SEEK_END);
    size_ = end > 0 ? static_cast<std::uint64_t>(end) : 0;
  }
  return {};
}

void OutputFile::sync() {
  sync_data(fd_, path_);
}

void OutputFile::end_direct() noexcept {
  if (fd_ < 0 || !direct_) return;
  if (end_direct_io(fd_)) direct_ = false;
}

bool end_direct_io(int fd) noexcept {
  const int flags = ::fcntl(fd, F_GETFL);
  if (flags < 0) return false;
  return (flags & O_DIRECT) == 0 || ::fcntl(fd, F_SETFL, flags & ~O_DIRECT) == 0;
}

bool direct_io_on(int fd) noexcept {
  const int flags = ::fcntl(fd, F_GETFL);
  return flags >= 0 && (flags & O_DIRECT) != 0;
}

bool cut_back(int fd, std::uint64_t size) noexcept {
  if (io::file_syscalls().ftruncate(fd, static_cast<off_t>(size)) != 0) return false;
  // A write after the cut continues at the cut, not past it (which would leave a hole).
  ::lseek(fd, static_cast<off_t>(size), SEEK_SET);
  return true;
}

OutputFile::~OutputFile() {
  if (fd_ >= 0) io::file_syscalls().close(fd_);
}

io::IoError OutputFile::try_write(std::span<const std::uint8_t> bytes) noexcept {
  if (const int error = write_fully(fd_, bytes, size_)) return {error, "cannot write", path_};
  return {};
}

int write_fully(int fd, std::span<const std::uint8_t> bytes, std::uint64_t& written) noexcept {
  while (!bytes.empty()) {
    const ssize_t n = io::file_syscalls().write(fd, bytes.data(), bytes.size());
    if (n < 0) {
      if (errno == EINTR) continue;
      return errno != 0 ? errno : EIO;
    }
    bytes = bytes.subspan(static_cast<std::size_t>(n));
    written += static_cast<std::uint64_t>(n);
  }
  return 0;
}

bool OutputFile::at_its_path() const noexcept {
  if (fd_ < 0) return true;
  struct stat open_file {
  }, named{};
  if (::fstat(fd_, &open_file) != 0) return true;  // cannot tell: the next write will say
  if (open_file.st_nlink == 0) return false;
  if (::stat(path_.c_str(), &named) != 0) return false;
  return named.st_ino == open_file.st_ino && named.st_dev == open_file.st_dev;
}

bool OutputFile::truncate(std::uint64_t size) noexcept {
  if (fd_ < 0 || !cut_back(fd_, size)) return false;
  size_ = size;
  return true;
}

io::IoError OutputFile::try_close() noexcept {
  if (fd_ < 0) return {};
  const int fd = fd_;
  fd_ = -1;
  if (io::file_syscalls().close(fd) != 0 && errno != EINTR) {
    return {errno != 0 ? errno : EIO, "cannot close", path_};
  }
  return {};
}

bool rename_no_replace(const char* from, const char* to) {
  if (::renameat2(AT_FDCWD, from, AT_FDCWD, to, RENAME_NOREPLACE) == 0) return true;
  if (errno == EEXIST) return false;
  if (errno != EINVAL && errno != ENOSYS) throw_errno("cannot rename to", to);
  // The file system has no RENAME_NOREPLACE: a hard link fails on an existing name too.
  if (::link(from, to) != 0) {
    if (errno == EEXIST) return false;
    throw_errno("cannot link to", to);
  }
  if (::unlink(from) != 0) throw_errno("cannot remove", from);
  return true;
}

void rename_replacing(const std::string& from, const std::string& to) {
  if (::rename(from.c_str(), to.c_str()) != 0) throw_errno("cannot rename to", to);
}

bool place_without_replacing(const std::string& from, std::string& to) {
  if (rename_no_replace(from.c_str(), to.c_str())) return false;
  const std::size_t name_at = to.rfind('/') + 1;
  // The extension the _dupN goes before: the last, or a compressed recording's two.
  std::size_t dot = to.ends_with(".pcap.zst") ? to.size() - 9 : to.rfind('.');
  if (dot == std::string::npos || dot < name_at) dot = to.size();
  const std::string extension = to.substr(dot);  // ".pcap", ".pcd" (a collision is rare)
  to.resize(dot);
  const std::size_t stem_size = to.size();
  for (unsigned n = 1;; ++n) {
    to.resize(stem_size);
    fmt::format_to(std::back_inserter(to), "_dup{}{}", n, extension);
    if (rename_no_replace(from.c_str(), to.c_str())) return true;
    if (n == 1000) {
      errno = EEXIST;
      throw_errno("no free name near", to);
    }
  }
}

std::pair<io::UniqueFd, std::uint64_t> open_leftover(const std::string& path, int access) {
  io::UniqueFd file(::open(path.c_str(), access | O_CLOEXEC | O_NOFOLLOW | O_NONBLOCK));
  if (!file) io::throw_errno("cannot open", path);
  struct stat info {};
  if (::fstat(file.get(), &info) != 0) io::throw_errno("cannot stat", path);
  if (!S_ISREG(info.st_mode)) io::throw_error(EINVAL, "not a regular file:", path);
  return {std::move(file), static_cast<std::uint64_t>(info.st_size)};
}

std::filesystem::path temporary_name(const std::filesystem::path& path) {
  std::string name;
  assign_temporary_name(name, path.native());
  return name;
}

void assign_temporary_name(std::string& out, std::string_view path) {
  const std::size_t name_at = path.rfind('/') + 1;  // npos + 1 == 0: no directory
  out.assign(path.substr(0, name_at));
  out += '.';
  out.append(path.substr(name_at));
  out += ".tmp";
}

namespace {

// `text` to `path` through its temporary name, its data synced first when `durable`.
void write_through_temporary(const std::filesystem::path& path, std::string_view text,
                             bool durable) {
  const std::filesystem::path temporary = temporary_name(path);
  try {
    OutputFile file(temporary, OutputFile::Mode::kCreate);
    file.write(text);
    if (durable) file.sync();
    file.close();
  } catch (...) {
    std::error_code ignored;
    std::filesystem::remove(temporary, ignored);
    throw;
  }
  rename_replacing(temporary.native(), path.native());
}

}  // namespace

void write_file_replacing(const std::filesystem::path& path, std::string_view text) {
  write_through_temporary(path, text, false);
}

void write_file_replacing(const std::string& path, const std::string& temporary,
                          std::string_view text, OutputFile& file) {
  try {
    file.open(temporary, OutputFile::Mode::kCreate);
    file.write(text);
    file.close();
  } catch (...) {
    ::unlink(temporary.c_str());
    throw;
  }
  rename_replacing(temporary, path);
}

void write_file_durably(const std::filesystem::path& path, std::string_view text) {
  write_through_temporary(path, text, true);
  std::string directory;
  assign_directory_of(directory, path.native());
  sync_directory(directory);
}

void sync_data(int fd, std::string_view path) {
  while (io::file_syscalls().fdatasync(fd) != 0) {
    if (errno != EINTR) throw_errno("cannot sync", path);
  }
}

void sync_directory(std::string_view directory) {
  const std::string name(directory);
  const io::UniqueFd fd(::open(name.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC));
  if (!fd) throw_errno("cannot open the directory", name);
  while (::fsync(fd.get()) != 0) {
    if (errno == EINVAL) return;  // a file system with nothing to sync for a directory
    if (errno != EINTR) throw_errno("cannot sync the directory", name);
  }
}

void assign_directory_of(std::string& out, std::string_view path) {
  const std::size_t slash = path.rfind('/');
  if (slash == std::string_view::npos) {
    out.assign(".");
  } else {
    out.assign(path.substr(0, slash == 0 ? 1 : slash));
  }
}

void sync_file(const std::string& path, AfterSync after) {
  const io::UniqueFd fd(::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NOFOLLOW));
  if (!fd) throw_errno("cannot open", path);
  sync_data(fd.get(), path);
  if (after == AfterSync::kDropCached) drop_cached_pages(fd.get());
}

void start_writeback(const std::string& path) noexcept {
  // Closed again at once: the writeback goes on without the descriptor, and a batch of files
  // holds none open while it waits.
  const io::UniqueFd fd(::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NOFOLLOW));
  // A file system without it (EINVAL, ESPIPE) is synced whole by fdatasync anyway.
  if (fd) ::sync_file_range(fd.get(), 0, 0, SYNC_FILE_RANGE_WRITE);
}

bool place_durably(const std::string& from, std::string& to) {
  // A recording an interrupted run left, read through to find its cut: out of the page cache
  // once synced, as the finisher leaves the recordings it places.
  sync_file(from, AfterSync::kDropCached);
  const bool renamed = place_without_replacing(from, to);
  std::string directory;
  assign_directory_of(directory, to);
  sync_directory(directory);
  return renamed;
}

}  // namespace pandarcap
