// Text from outside (configured paths, file names, what the network sends) made safe for a log
// line: every control character (bytes 0x00-0x1F and 0x7F) becomes `\xNN`, so a newline in a
// file name cannot start a forged log line, and an escape sequence cannot reach a terminal.
// Everything else is kept, UTF-8 included. Escaping twice changes nothing (the result has no
// control character left).
//   escaped_control("out\n[info] ok") == "out\x0a[info] ok"
#pragma once

#include <string>
#include <string_view>

namespace pandarcap {

inline bool is_control(char c) noexcept {
  const auto u = static_cast<unsigned char>(c);
  return u < 0x20 || u == 0x7F;
}

// Appends `text`, escaped, to `out` (any container of char with push_back: std::string, fmt's
// memory buffers).
template <typename Out>
void append_escaped_control(std::string_view text, Out& out) {
  constexpr char kHex[] = "0123456789abcdef";
  for (const char c : text) {
    if (!is_control(c)) {
      out.push_back(c);
      continue;
    }
    const auto u = static_cast<unsigned char>(c);
    out.push_back('\\');
    out.push_back('x');
    out.push_back(kHex[u >> 4]);
    out.push_back(kHex[u & 0xF]);
  }
}

std::string escaped_control(std::string_view text);

}  // namespace pandarcap
