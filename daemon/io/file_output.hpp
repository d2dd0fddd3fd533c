// The daemon's thin layer over the files it writes: every failing system call becomes one
// std::system_error carrying errno and the path ("cannot write 'x'"), EINTR and short writes are
// retried in one place, and finished files appear only under their final name (written under a
// temporary name in the same directory, then renamed: readers never see half a file).
//
// Durable before visible: a power cut must not leave a file under its final name with less in it
// than it was written with. A rename reaches the disk's journal independently of the file's data
// (ext4's delayed allocation writes the data seconds later), so a file's data is synced
// (sync_data) before its rename, and its directory (sync_directory) after, or the new name may
// not survive either. In the writer's loop that is the finisher thread's job
// (daemon/output/file_finisher.hpp); at start-up, write_file_durably() and place_durably().
#pragma once

#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <string_view>
#include <utility>

#include "daemon/io/errors.hpp"
#include "daemon/io/unique_fd.hpp"

namespace pandarcap {

class OutputFile {
 public:
  // kCreateDirect: create, past the page cache (O_DIRECT) when the file system allows it (else
  // as kCreate; direct() says which). While direct, each write must be whole 4096-byte blocks
  // from 4096-aligned memory; end_direct() then lets an unaligned tail follow.
  enum class Mode { kCreate, kAppend, kCreateDirect };
  OutputFile() = default;  // closed; open() it
  // Opens (creating, truncating for kCreate) `path`. Throws std::system_error.
  OutputFile(const std::filesystem::path& path, Mode mode) { open(path.native(), mode); }
  ~OutputFile();
  // Opens another file with this object (closing the current one). Reusing one OutputFile keeps
  // its path buffer, so reopening allocates nothing once the buffer has grown.
  void open(std::string_view path, Mode mode) {
    if (const io::IoError error = try_open(path, mode)) io::throw_io_error(error);
  }
  // The same, the failure returned instead of thrown (the writer's loop: no exception, nothing
  // allocated). After a failure the file is closed. A file created counts, with the CPU its
  // open() took, in io::file_creations().
  io::IoError try_open(std::string_view path, Mode mode);
  bool is_open() const noexcept { return fd_ >= 0; }
  // Room for a path of `bytes` made now (at start-up): the first open() allocates nothing.
  void reserve_path(std::size_t bytes) { path_.reserve(bytes); }
  // Two files trade places, descriptor, path (and its reserve) and state: nothing allocated.
  void swap(OutputFile& other) noexcept {
    path_.swap(other.path_);
    std::swap(fd_, other.fd_);
    std::swap(size_, other.size_);
    std::swap(direct_, other.direct_);
  }
  OutputFile(const OutputFile&) = delete;
  OutputFile& operator=(const OutputFile&) = delete;

  void write(std::span<const std::uint8_t> bytes) {
    if (const io::IoError error = try_write(bytes)) io::throw_io_error(error);
  }
  void write(std::string_view text) { write(as_bytes(text)); }
  // The same, returning the failure (the bytes written before it stay written: size() says).
  io::IoError try_write(std::span<const std::uint8_t> bytes) noexcept;
  io::IoError try_write(std::string_view text) noexcept { return try_write(as_bytes(text)); }
  bool direct() const noexcept { return direct_; }
  // The descriptor, for a thread that appends through it while this object's owner writes
  // nothing (an MCAP file's chunks, daemon/mcap/chunk_pipeline.hpp); -1 when closed. What that
  // thread wrote is counted into size() with count_written() once its owner learns of it.
  int fd() const noexcept { return fd_; }
  void count_written(std::uint64_t bytes) noexcept { size_ += bytes; }
  // fdatasync(2): what was written is on the disk (at start-up; the writer's loop leaves this to
  // the finisher thread). Throws std::system_error.
  void sync();
  // Back to writes through the page cache (for a file's unaligned tail). Best effort: no throw.
  void end_direct() noexcept;
  // Closes, reporting a failed close (a deferred write error on some file systems).
  void close() {
    if (const io::IoError error = try_close()) io::throw_io_error(error);
  }
  io::IoError try_close() noexcept;
  // Cuts the file back to `size` bytes (after a failed write), best effort: no throw; false when
  // the cut failed. The next write continues there.
  bool truncate(std::uint64_t size) noexcept;
  std::uint64_t size() const noexcept { return size_; }
  const std::string& path() const noexcept { return path_; }
  // Whether the open file is still the one its path names: false once it was removed (with its
  // directory, say) or its directory replaced (a remount), when what is written here reaches no
  // reader. True for a closed file.
  bool at_its_path() const noexcept;

 private:
  io::IoError open_file(std::string_view path, Mode mode);
  static std::span<const std::uint8_t> as_bytes(std::string_view text) noexcept {
    return {reinterpret_cast<const std::uint8_t*>(text.data()), text.size()};
  }

  std::string path_;
  int fd_ = -1;
  std::uint64_t size_ = 0;  // for kAppend: the size at open plus what was written
  bool direct_ = false;
};

// Writes all of `bytes` to `fd` at its position through the test seam (io::file_syscalls),
// retrying EINTR and short writes, and adds what was written to `written`. Returns 0, or the
// errno of the write that failed (the bytes before it stay written). OutputFile::try_write's
// loop, for a thread that writes through an OutputFile's descriptor.
int write_fully(int fd, std::span<const std::uint8_t> bytes, std::uint64_t& written) noexcept;
// Whether `fd` writes past the page cache (O_DIRECT) now.
bool direct_io_on(int fd) noexcept;
// `fd`'s writes through the page cache from now on (OutputFile::end_direct's call); false when
// the kernel refused.
bool end_direct_io(int fd) noexcept;
// `fd` cut back to `size` bytes (the seam's ftruncate), its next write at the cut
// (OutputFile::truncate's calls); false when the cut failed.
bool cut_back(int fd, std::uint64_t size) noexcept;

// The block size and alignment O_DIRECT writes are made in (the page size: every file system's
// logical block size divides it).
inline constexpr std::size_t kDirectIoBlock = 4096;
// `bytes` rounded up to whole kDirectIoBlock blocks.
constexpr std::size_t whole_direct_blocks(std::size_t bytes) noexcept {
  return (bytes + kDirectIoBlock - 1) / kDirectIoBlock * kDirectIoBlock;
}

// Gives `from` the name `to` unless a file of that name exists: renameat2(RENAME_NOREPLACE), or,
// on a file system without it, link + unlink (which refuse an existing name just the same).
// Returns false, with both files untouched, when `to` exists. Throws std::system_error for any
// other failure.
bool rename_no_replace(const char* from, const char* to);

// Renames `from` to `to`, replacing a file of that name (health files: the newest replaces the
// last, health.jsonl rotates to health.jsonl.1). Throws std::system_error.
void rename_replacing(const std::string& from, const std::string& to);

// Puts a finished recording (`from`, a temporary or .part name) in place as `to` without ever
// replacing a file: when `to` exists, the first free name of "STEM_dupN.EXT" (N = 1, 2, ...) is
// taken instead. Returns the name used and whether it had to differ from `to` (the caller counts
// and logs that: it means file names repeated, which they should not). `to` itself is reused as
// the buffer for the new name (no allocation once it has grown). Throws std::system_error.
bool place_without_replacing(const std::string& from, std::string& to);

// Writes `text` to `path` through a temporary file in the same directory and a rename.
void write_file_replacing(const std::filesystem::path& path, std::string_view text);
// The same, durable: the data synced before the rename and the directory after, so a power cut
// leaves either the old file whole or the new one whole (raw/calibration.csv, raw/sensor.json, at
// start-up). Throws std::system_error.
void write_file_durably(const std::filesystem::path& path, std::string_view text);

// fdatasync(2) of `fd` (`path` names it in the error), through the test seam. Throws
// std::system_error.
void sync_data(int fd, std::string_view path);
// What sync_file does with the file's pages once they are on the disk.
enum class AfterSync : std::uint8_t {
  kKeepCached,
  // Dropped from the page cache (posix_fadvise POSIX_FADV_DONTNEED, best effort): a recording is
  // written once and read again rarely, so its pages only crowd out what is read. The kernel drops
  // clean pages only: what was written after the sync stays until the next one. Freed pages are
  // what the next writes are given, where fresh ones cost far more than the copy into them on a
  // virtual machine that backs guest memory lazily (docs/performance.md, "Seventh round").
  kDropCached,
};
// fdatasync(2) of the file named `path` (opened read-only, never through a link: fdatasync flushes
// the file, whichever descriptor asks), then `after`. Throws std::system_error.
void sync_file(const std::string& path, AfterSync after);
// The file named `path`'s dirty pages sent on their way to the disk (sync_file_range: start, do
// not wait), so that syncing several files one after the other waits for the slowest, not for
// their sum. Best effort: no throw (the sync that follows reports what fails).
void start_writeback(const std::string& path) noexcept;
// fsync(2) of the directory `directory`, so the names made, renamed or removed in it survive a
// power cut. A file system that cannot sync a directory (EINVAL: some FUSE, NFS) has nothing to
// sync: not an error. Throws std::system_error.
void sync_directory(std::string_view directory);
// The directory part of `path` ("a/b/c.pcap" -> "a/b"; "c.pcap" -> ".") into `out`, its capacity
// reused.
void assign_directory_of(std::string& out, std::string_view path);

// put_in_place's durable form for start-up (a recording an interrupted run left, finished): the
// file's data synced (and its pages dropped: AfterSync::kDropCached), then renamed without
// replacing (see place_without_replacing), then its directory synced. Returns whether the name had
// to differ. Throws std::system_error.
bool place_durably(const std::string& from, std::string& to);
// The same with the temporary name and the file object given, for a file rewritten every second:
// nothing is allocated.
void write_file_replacing(const std::string& path, const std::string& temporary,
                          std::string_view text, OutputFile& file);

// The temporary name used for `path` while it is being written: ".<name>.tmp", hidden from
// globs such as *.pcd and *.prom (node_exporter's textfile collector reads only *.prom).
std::filesystem::path temporary_name(const std::filesystem::path& path);
// The same into `out` (its capacity reused: no allocation once it has grown).
void assign_temporary_name(std::string& out, std::string_view path);

// Opens a file an interrupted run left, to finish it (`access`: O_RDONLY or O_RDWR): never through
// a symbolic link (O_NOFOLLOW: a link in an output directory never leads a cut to a file
// elsewhere), never hanging the start on a FIFO put there (O_NONBLOCK); anything but a regular
// file is refused. Returns the descriptor and the file's size. Throws std::system_error naming
// the path.
std::pair<io::UniqueFd, std::uint64_t> open_leftover(const std::string& path, int access);

}  // namespace pandarcap
