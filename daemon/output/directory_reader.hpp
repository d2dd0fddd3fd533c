// One directory's regular files, read without allocating: getdents64 into a buffer the owner
// allocated at start-up (opendir would allocate), each file that passes a name test stat'ed
// (fstatat, not following links). The free-space floor and the upload backlog read the output
// directories with it. A read can stop after any file and go on from there later (the backlog
// reads a little each second); the position is the open descriptor's and the buffer's.
//
//   DirectoryReader reader(buffer);
//   if (reader.open("/data/raw")) {
//     DirectoryReader::File file;
//     while (reader.next(file, [](std::string_view name) { return name.ends_with(".pcap"); })) ...
//   }
// Owned by one thread.
#pragma once

#include <sys/stat.h>

#include <cstdint>
#include <span>
#include <string_view>

namespace pandarcap {

class DirectoryReader {
 public:
  explicit DirectoryReader(std::span<char> buffer) noexcept : buffer_(buffer) {}
  ~DirectoryReader() { close(); }
  DirectoryReader(const DirectoryReader&) = delete;
  DirectoryReader& operator=(const DirectoryReader&) = delete;

  // Starts reading `directory` (a read in progress is dropped). False when it cannot be opened
  // (gone, not a directory): nothing to read.
  bool open(const char* directory) noexcept;
  bool is_open() const noexcept { return fd_ >= 0; }
  void close() noexcept;

  struct File {
    std::string_view name;  // valid until the next call
    struct stat info;
  };
  // The next regular file whose name `wanted` accepts, stat'ed; false at the end (the directory
  // is then closed). A link, a directory or a device is never returned, whatever its name.
  template <typename Wanted>
  bool next(File& file, Wanted&& wanted) noexcept {
    while (next_entry(file.name)) {
      if (!wanted(file.name)) continue;
      if (stat_entry(file)) return true;
    }
    return false;
  }

 private:
  // The next entry that may be a regular file (by its d_type), or false at the end.
  bool next_entry(std::string_view& name) noexcept;
  bool stat_entry(File& file) noexcept;

  std::span<char> buffer_;
  int fd_ = -1;
  long filled_ = 0, at_ = 0;  // bytes the last getdents64 gave, and the next entry's offset
  const char* name_ = nullptr;
};

}  // namespace pandarcap
