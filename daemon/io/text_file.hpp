// Reading the operator's small text files (configuration, calibration) whole, with a bound: they
// are a few kB, and a wrong path such as /dev/zero, a FIFO or a huge file must be an error with
// a location, not memory exhausted or a wait before the parser could say what is wrong.
#pragma once

#include <cstddef>
#include <string>

namespace pandarcap {

inline constexpr std::size_t kMaxOperatorFileBytes = 1 << 20;

struct TextFile {
  // kNotRegular: a FIFO, socket, device or directory, refused without reading (a FIFO with no
  // writer would never end).
  enum class Status { kOk, kCannotOpen, kNotRegular, kCannotRead, kTooLarge } status = Status::kOk;
  int error_number = 0;  // errno for kCannotOpen / kCannotRead
  std::string text;      // the whole file for kOk
};

// Reads `path` whole if it holds at most `max_bytes`.
TextFile read_text_file(const std::string& path, std::size_t max_bytes = kMaxOperatorFileBytes);

}  // namespace pandarcap
