#include "text_file.hpp"

#include <cerrno>
#include <fstream>

namespace pandarcap {

TextFile read_text_file(const std::string& path, std::size_t max_bytes) {
  TextFile file;
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    file.status = TextFile::Status::kCannotOpen;
    file.error_number = errno;
    return file;
  }
  // One byte more than allowed: reading it means the file is too large.
  file.text.assign(max_bytes + 1, '\0');
  in.read(file.text.data(), static_cast<std::streamsize>(file.text.size()));
  if (in.bad()) {
    file.status = TextFile::Status::kCannotRead;
    file.error_number = errno;
    file.text.clear();
    return file;
  }
  file.text.resize(static_cast<std::size_t>(in.gcount()));
  if (file.text.size() > max_bytes) {
    file.status = TextFile::Status::kTooLarge;
    file.text.clear();
  }
  return file;
}

}  // namespace pandarcap
