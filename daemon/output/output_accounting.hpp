// What the writer's outputs count in common: failed writes and names found taken.
//
// Every part that writes files (frames, recordings, health files, the start-up clean-up) reports
// here, so health sees one write_errors / bytes_not_written / output_name_collisions for the
// whole writer, and one "last error" text to quote in its reason. A failed write is logged at
// most every 10 s (a full disk fails every frame). The last error's text is kept in a buffer of
// fixed size (cut to fit), and a failure from the writer's loop comes as an io::IoError whose
// text is made there: counting a failed write allocates nothing. Owned by the writer thread; not
// thread-safe.
#pragma once

#include <array>
#include <cstdint>
#include <exception>
#include <string>
#include <string_view>

#include "daemon/io/errors.hpp"

namespace pandarcap {

class OutputAccounting {
 public:
  // A write failed: one write error, `bytes` not written, logged unless one was within 10 s.
  // The error's text is kept for the health reason (its capacity reused).
  void write_failed(const std::exception& error, std::uint64_t bytes) {
    write_failed(std::string_view(error.what()), bytes);
  }
  // The same with the reason in words (a write refused to keep space for health).
  void write_failed(std::string_view reason, std::uint64_t bytes);
  // The same for a failed file operation ("cannot write 'x': No space left on device").
  void write_failed(const io::IoError& error, std::uint64_t bytes);
  // Bytes given up without trying to write them (the rest of a batch after the disk failed).
  void not_written(std::uint64_t bytes) noexcept { bytes_not_written_ += bytes; }

  // Renames a finished file from `from` to `to` without replacing anything (see file_output);
  // on a collision `to` becomes the name used, counted and logged.
  void put_in_place(const std::string& from, std::string& to);
  // A file put in place under `used` because the name it was meant for was taken (a name that
  // repeated, which it should not): counted and logged.
  void name_collision(std::string_view from, std::string_view used);

  std::uint64_t write_errors() const noexcept { return write_errors_; }
  std::uint64_t bytes_not_written() const noexcept { return bytes_not_written_; }
  std::uint64_t name_collisions() const noexcept { return name_collisions_; }
  std::string_view last_error() const noexcept { return {last_error_.data(), last_error_size_}; }

  // The longest last-error text kept: a path of a few hundred characters and errno's words.
  static constexpr std::size_t kLastErrorCapacity = 1024;

 private:
  void count_and_log(std::uint64_t bytes);

  std::uint64_t write_errors_ = 0, bytes_not_written_ = 0;
  std::uint64_t name_collisions_ = 0;
  std::int64_t last_error_log_ns_ = -1;
  std::array<char, kLastErrorCapacity> last_error_{};
  std::size_t last_error_size_ = 0;
};

}  // namespace pandarcap
