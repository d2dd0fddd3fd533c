// The writer's thin layer over files: every failing system call becomes one std::system_error
// carrying errno and the path ("cannot write 'x'"), EINTR and short writes are retried in one
// place, and finished files appear only under their final name (written under a temporary name
// in the same directory, then renamed: readers never see half a file).
#pragma once

#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <string_view>

namespace pandarcap {

class OutputFile {
 public:
  enum class Mode { kCreate, kAppend };
  // Opens (creating, truncating for kCreate) `path`. Throws std::system_error.
  OutputFile(std::filesystem::path path, Mode mode);
  ~OutputFile();
  OutputFile(const OutputFile&) = delete;
  OutputFile& operator=(const OutputFile&) = delete;

  void write(std::span<const std::uint8_t> bytes);
  void write(std::string_view text) {
    write(std::span(reinterpret_cast<const std::uint8_t*>(text.data()), text.size()));
  }
  // Closes, reporting a failed close (a deferred write error on some file systems).
  void close();
  std::uint64_t size() const noexcept { return size_; }
  const std::filesystem::path& path() const noexcept { return path_; }

 private:
  std::filesystem::path path_;
  int fd_ = -1;
  std::uint64_t size_ = 0;  // for kAppend: the size at open plus what was written
};

// Writes `text` to `path` through a temporary file in the same directory and a rename.
void write_file_replacing(const std::filesystem::path& path, std::string_view text);

// The temporary name used for `path` while it is being written: ".<name>.tmp", hidden from
// globs such as *.pcd and *.prom (node_exporter's textfile collector reads only *.prom).
std::filesystem::path temporary_name(const std::filesystem::path& path);

// "20261122T120000.123Z" (with_millis) or "20261122T120000Z", for file names.
std::string utc_file_stamp(std::int64_t unix_ns, bool with_millis);

}  // namespace pandarcap
