// What the writer's outputs count in common: failed writes and names found taken.
//
// Every part that writes files (frames, recordings, health files, the start-up clean-up) reports
// here, so health sees one write_errors / bytes_not_written / output_name_collisions for the
// whole writer, and one "last error" text to quote in its reason. A failed write is logged at
// most every 10 s (a full disk fails every frame). Owned by the writer thread; not thread-safe.
#pragma once

#include <cstdint>
#include <exception>
#include <string>
#include <string_view>

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
  const std::string& last_error() const noexcept { return last_error_; }

 private:
  std::uint64_t write_errors_ = 0, bytes_not_written_ = 0;
  std::uint64_t name_collisions_ = 0;
  std::int64_t last_error_log_ns_ = -1;
  std::string last_error_;
};

}  // namespace pandarcap
