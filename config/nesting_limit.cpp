#include "config/nesting_limit.hpp"

#include <fmt/format.h>

#include <cstddef>
#include <cstdint>

#include "config/config_loader.hpp"

namespace pandarcap::config_detail {

void reject_deep_nesting(std::string_view text, const std::string& source_name) {
  std::size_t line = 1, column = 0;
  int depth = 0;                    // open [ and {
  std::uint64_t inline_tables = 0;  // bit d: the bracket open at depth d+1 is a '{'
  bool in_key = true;               // before the '=' of a key, or inside a table header
  int key_dots = 0;
  const auto too_deep = [&] {
    throw ConfigError(fmt::format(
        "{}:{}:{}: nested more than {} levels deep (tables, dotted keys, arrays): not a "
        "pandarcapd configuration",
        source_name, line, column, kMaxNesting));
  };
  for (std::size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    ++column;
    if (c == '\n') {
      ++line;
      column = 0;
      if (depth == 0) {
        in_key = true;
        key_dots = 0;
      }
      continue;
    }
    if (c == '#') {  // comment: to the end of the line
      while (i + 1 < text.size() && text[i + 1] != '\n')
        ++i;
      continue;
    }
    if (c == '"' || c == '\'') {
      const bool multi_line = text.substr(i, 3) == std::string_view(c == '"' ? "\"\"\"" : "'''");
      const std::string_view close = multi_line ? text.substr(i, 3) : text.substr(i, 1);
      i += close.size() - 1;
      // To the closing quote(s); a basic string's backslash escapes the next character. An
      // unterminated string is left to toml++ to report.
      while (i + 1 < text.size()) {
        ++i;
        ++column;
        if (text[i] == '\n') {
          ++line;
          column = 0;
          if (!multi_line) break;
        } else if (c == '"' && text[i] == '\\') {
          ++i;
          ++column;
        } else if (text.substr(i, close.size()) == close) {
          i += close.size() - 1;
          column += close.size() - 1;
          break;
        }
      }
      continue;
    }
    switch (c) {
      case '[':
      case '{':
        if (depth + key_dots + 1 > kMaxNesting) too_deep();
        if (c == '{') {
          inline_tables |= std::uint64_t{1} << depth;
          in_key = true;  // an inline table's keys follow
          key_dots = 0;
        } else {
          inline_tables &= ~(std::uint64_t{1} << depth);
        }
        ++depth;
        break;
      case ']':
      case '}':
        if (depth > 0) --depth;
        if (c == '}') in_key = false;
        break;
      case ',':
        if (depth > 0 && (inline_tables >> (depth - 1) & 1) != 0) {
          in_key = true;
          key_dots = 0;
        }
        break;
      case '=':
        in_key = false;
        break;
      case '.':
        if (in_key && depth + ++key_dots + 1 > kMaxNesting) too_deep();
        break;
      default:
        break;
    }
  }
}

}  // namespace pandarcap::config_detail
