#include "daemon/io/errors.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <string>
#include <system_error>

namespace pandarcap::io {

void throw_error(int error, std::string_view what) {
  throw std::system_error(error != 0 ? error : EIO, std::generic_category(), std::string(what));
}

void throw_error(int error, std::string_view what, std::string_view path) {
  std::string message(what);
  message += " '";
  message += path;
  message += '\'';
  throw_error(error, message);
}

std::size_t format_io_error(const IoError& error, std::span<char> out) noexcept {
  // strerrordesc_np: the text strerror gives (and std::generic_category().message()), from a
  // static table, without strerror's buffer for an unknown number.
  const int code = error.code != 0 ? error.code : EIO;
  const char* description = ::strerrordesc_np(code);
  try {
    const auto written = description != nullptr
                             ? fmt::format_to_n(out.data(), out.size(), "{} '{}': {}", error.what,
                                                error.path, description)
                             : fmt::format_to_n(out.data(), out.size(), "{} '{}': Unknown error {}",
                                                error.what, error.path, code);
    return std::min(written.size, out.size());
  } catch (...) {
    return 0;  // fmt reports no error for these arguments
  }
}

void throw_io_error(const IoError& error) {
  throw_error(error.code, error.what, error.path);
}

void throw_errno(std::string_view what) {
  throw_error(errno, what);
}

void throw_errno(std::string_view what, std::string_view path) {
  throw_error(errno, what, path);
}

}  // namespace pandarcap::io
