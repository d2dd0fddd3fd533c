#include "daemon/io/errors.hpp"

#include <cerrno>
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

void throw_errno(std::string_view what) {
  throw_error(errno, what);
}

void throw_errno(std::string_view what, std::string_view path) {
  throw_error(errno, what, path);
}

}  // namespace pandarcap::io
