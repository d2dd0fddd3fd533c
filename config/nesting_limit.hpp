// A guard in front of toml++: it parses nesting by recursion, so a dotted key or table header
// some 40 000 levels deep (an 80 KB file) would overflow the stack. A pandarcapd configuration
// nests two levels; text nested deeper than kMaxNesting is refused before toml++ sees it.
// Internal to config/.
#pragma once

#include <string>
#include <string_view>

namespace pandarcap::config_detail {

// Counted: open arrays and inline tables, plus the dots of the key or table header being read
// (dots inside strings and comments, and in values such as 1.5, are not keys and do not count).
inline constexpr int kMaxNesting = 32;

// Throws ConfigError at `source_name:line:col`, the character where the limit is crossed.
void reject_deep_nesting(std::string_view text, const std::string& source_name);

}  // namespace pandarcap::config_detail
