// The one place a failed system call becomes an exception, or an error code.
//
// Every file and socket call in the daemon reports failure the same way: a std::system_error that
// carries the errno (callers branch on it: ENOSPC, EEXIST, EWOULDBLOCK...) and says what was being
// done and to what ("cannot write 'raw/x.pcap.part'"). Nothing outside daemon/io/ and daemon/pcap/
// builds one by hand.
//
// The writer's loop cannot afford an exception: throwing allocates (the exception object, its
// text), and a full disk fails every frame. There the same facts travel as an IoError (errno,
// what was being done, the file), and their text is made only where it is kept, into a buffer
// that is already there (format_io_error): the text is the one the exception would carry.
#pragma once

#include <cstddef>
#include <span>
#include <string_view>

namespace pandarcap::io {

// A failed file operation: its errno (0: none), what was being done ("cannot write", a string
// literal) and to which file (a view of the caller's path: valid while that file object is).
struct IoError {
  int code = 0;
  const char* what = "";
  std::string_view path;

  explicit operator bool() const noexcept { return code != 0; }
};

// "WHAT 'PATH': STRERROR", as the std::system_error for it would say, into `out` (cut to fit,
// not terminated); returns the characters written. Allocates nothing.
std::size_t format_io_error(const IoError& error, std::span<char> out) noexcept;
// Throws the std::system_error for `error` (where an exception is fine: start-up, tools).
[[noreturn]] void throw_io_error(const IoError& error);

// Throws std::system_error for `error` with the message `what` ("simulator socket").
[[noreturn]] void throw_error(int error, std::string_view what);
// The same for `what 'path'` ("cannot open '/var/lib/pandarcap/frames/x.pcd'").
[[noreturn]] void throw_error(int error, std::string_view what, std::string_view path);

// The same with the current errno (read first, before anything can change it). An errno of 0
// (stdio is not obliged to set it) is reported as EIO rather than as "Success".
[[noreturn]] void throw_errno(std::string_view what);
[[noreturn]] void throw_errno(std::string_view what, std::string_view path);

}  // namespace pandarcap::io
