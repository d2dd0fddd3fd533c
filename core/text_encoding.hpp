// Text for the outside world's parsers, shared by the health formats: JSON strings and numbers,
// and Prometheus label values. Pure; each appends to a buffer whose capacity it reuses.
#pragma once

#include <string>
#include <string_view>

namespace pandarcap {

// Appends `value` escaped as a Prometheus label value (backslash, double quote, newline): to a
// std::string, or to a stack buffer (fmt::memory_buffer) a label is built in.
template <typename Buffer>
void append_label_value(Buffer& out, std::string_view value) {
  for (const char c : value) {
    if (c == '\\' || c == '"') {
      out.push_back('\\');
      out.push_back(c);
    } else if (c == '\n') {
      out.push_back('\\');
      out.push_back('n');
    } else {
      out.push_back(c);
    }
  }
}

// The same, as a new string.
std::string escape_label_value(std::string_view value);

// A JSON string. Bytes that are not valid UTF-8 (an error message may carry some) become U+FFFD.
void append_json_string(std::string& out, std::string_view s);

// A JSON number; JSON has no NaN or infinity, so those become null.
void append_json_number(std::string& out, double v);

}  // namespace pandarcap
