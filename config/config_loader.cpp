// The TOML configuration, read with toml++.
//
// One list of keys (for_each_key) drives everything: reading the file, the range checks, the
// unknown-key check and printing. Adding a key means adding one line there, so the file format,
// the checks and `--print-config` cannot drift apart.
#include "config/config_loader.hpp"

#include <fmt/format.h>
#include <toml++/toml.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cstdlib>
#include <cstring>
#include <map>
#include <span>
#include <type_traits>
#include <variant>
#include <vector>

#include "config/config_checks.hpp"
#include "config/config_keys.hpp"
#include "config/nesting_limit.hpp"
#include "config/suggest.hpp"
#include "config/value_checks.hpp"
#include "core/log_text.hpp"
#include "daemon/io/text_file.hpp"

namespace pandarcap {

using namespace config_detail;

ConfigError::ConfigError(const std::string& message)
    : std::runtime_error(escaped_control(message)) {}

ConfigError ConfigError::lines(const std::vector<std::string>& problems) {
  std::string joined;
  for (const std::string& problem : problems) {
    if (!joined.empty()) joined += '\n';
    append_escaped_control(problem, joined);
  }
  return ConfigError(Joined{}, joined);
}

namespace {

// Reads each known key from the document into the configuration, checking its type and that
// an integer fits its field, and records where it was.
struct FileReader {
  const toml::table& root;
  const Reporter& report;
  Positions& positions;

  const toml::node* find(std::string_view table, std::string_view key) const {
    const toml::node* holder = table.empty() ? &root : root.get(table);
    if (holder == nullptr || !holder->is_table()) return nullptr;
    const toml::node* node = holder->as_table()->get(key);
    if (node != nullptr) positions[dotted(table, key)] = node->source().begin;
    return node;
  }

  [[noreturn]] void wrong_type(const toml::node& n, std::string_view table, std::string_view key,
                               std::string_view expected) const {
    report.fail_at(n.source().begin, dotted(table, key),
                   fmt::format("expected {}, found {}", expected, type_name(n.type())));
  }

  static std::string_view type_name(toml::node_type t) {
    switch (t) {
      case toml::node_type::string:
        return "a string";
      case toml::node_type::integer:
        return "an integer";
      case toml::node_type::floating_point:
        return "a floating-point number";
      case toml::node_type::boolean:
        return "a boolean";
      case toml::node_type::table:
        return "a table";
      case toml::node_type::array:
        return "an array";
      default:
        return "a date or time";
    }
  }

  void operator()(std::string_view table, std::string_view key, std::string& out,
                  StringCheck) const {
    if (const auto* n = find(table, key)) {
      if (!n->is_string()) wrong_type(*n, table, key, "a string");
      out = n->as_string()->get();
    }
  }
  void operator()(std::string_view table, std::string_view key, bool& out, std::monostate) const {
    if (const auto* n = find(table, key)) {
      if (!n->is_boolean()) wrong_type(*n, table, key, "true or false");
      out = n->as_boolean()->get();
    }
  }
  template <typename Int>
  void operator()(std::string_view table, std::string_view key, Int& out, IntRange r) const {
    if (const auto* n = find(table, key)) {
      if (!n->is_integer()) wrong_type(*n, table, key, "an integer");
      const std::int64_t v = n->as_integer()->get();
      // Checked here, before narrowing, so 65537 cannot wrap to a valid port.
      if (v < r.lo || v > r.hi) {
        report.fail_at(n->source().begin, dotted(table, key),
                       fmt::format("{} is out of range ({}..{})", v, r.lo, r.hi));
      }
      out = static_cast<Int>(v);
    }
  }
  void operator()(std::string_view table, std::string_view key, double& out, RealRange) const {
    if (const auto* n = find(table, key)) {
      if (n->is_floating_point()) {
        out = n->as_floating_point()->get();
      } else if (n->is_integer()) {  // `max_range = 200` means 200.0
        out = static_cast<double>(n->as_integer()->get());
      } else {
        wrong_type(*n, table, key, "a number");
      }
    }
  }
};

// Every table and key in the document must be one the configuration has. Each that is not is a
// problem, with the nearest known name when one is near ("did you mean data_port?"), or the
// table a key belongs in when it was put in another.
std::vector<Problem> unknown_keys(const toml::table& root, const std::string& source_name) {
  std::map<std::string, std::vector<std::string_view>, std::less<>> known;
  DaemonConfig probe;
  for_each_key(probe, [&](std::string_view table, std::string_view key, auto&, auto) {
    known[std::string(table)].push_back(key);
  });
  std::vector<std::string_view> top_names;  // tables and top-level keys
  for (const auto& [table, keys] : known) {
    if (table.empty()) {
      top_names.insert(top_names.end(), keys.begin(), keys.end());
    } else {
      top_names.push_back(table);
    }
  }
  const auto hint = [&](std::string_view name, std::span<const std::string_view> candidates,
                        std::string_view table) -> std::string {
    if (const auto near = nearest(name, candidates))
      return fmt::format(" (did you mean {}?)", *near);
    for (const auto& [other, keys] : known) {
      if (other != table && std::find(keys.begin(), keys.end(), name) != keys.end()) {
        return other.empty() ? fmt::format(" ({} is a top-level key, before any table)", name)
                             : fmt::format(" ({} is a key of [{}])", name, other);
      }
    }
    return "";
  };
  std::vector<Problem> problems;
  const auto note = [&](const toml::source_position& at, const std::string& key,
                        const std::string& message) {
    problems.push_back(Problem{
        at, fmt::format("{}:{}:{}: {}: {}", source_name, at.line, at.column, key, message)});
  };
  const auto& top = known[""];
  for (const auto& [key, node] : root) {
    const std::string name(key.str());
    const auto table = known.find(name);
    if (table == known.end() || name.empty()) {
      if (std::find(top.begin(), top.end(), name) == top.end())
        note(key.source().begin, name, "unknown key or table" + hint(name, top_names, ""));
      continue;
    }
    if (!node.is_table()) {
      note(node.source().begin, name,
           fmt::format("expected a table, found {}", FileReader::type_name(node.type())));
      continue;
    }
    for (const auto& [inner, inner_node] : *node.as_table()) {
      const std::string_view inner_name = inner.str();
      if (std::find(table->second.begin(), table->second.end(), inner_name) ==
          table->second.end()) {
        note(inner.source().begin, dotted(name, inner_name),
             "unknown key" + hint(inner_name, table->second, name));
      }
    }
  }
  return problems;
}

std::string toml_string(const std::string& s) {
  std::string out = "\"";
  for (const char c : s) {
    const auto u = static_cast<unsigned char>(c);
    if (c == '"' || c == '\\') {
      out += '\\';
      out += c;
    } else if (u < 0x20 || u == 0x7F) {
      out += fmt::format("\\u{:04X}", u);
    } else {
      out += c;
    }
  }
  return out + '"';
}

// Shortest text that reads back to the same double, always with a '.' or exponent so TOML
// reads it as a float.
std::string toml_real(double v) {
  std::string text = fmt::format("{}", v);
  if (text.find_first_of(".eEn") == std::string::npos) text += ".0";
  return text;
}

}  // namespace

DaemonConfig parse_config(std::string_view toml_text, const std::string& source_name) {
  reject_deep_nesting(toml_text, source_name);
  toml::table root;
  try {
    root = toml::parse(toml_text, source_name);
  } catch (const toml::parse_error& e) {
    const auto& at = e.source().begin;
    throw ConfigError(
        fmt::format("{}:{}:{}: {}", source_name, at.line, at.column, e.description()));
  }
  Positions positions;
  const Reporter report(source_name, &positions);
  std::vector<Problem> problems = unknown_keys(root, source_name);
  DaemonConfig config;
  const FileReader reader{root, report, positions};
  for_each_key(
      config, [&](std::string_view table, std::string_view key, auto& out, const auto& check) {
        collect(problems, positions, dotted(table, key), [&] { reader(table, key, out, check); });
      });
  // A key that could not be read keeps its default, which passes; what was read is checked.
  check_values(config, report, positions, problems);
  throw_if_any(problems);
  return config;
}

DaemonConfig load_config_file(const std::filesystem::path& path) {
  const TextFile file = read_text_file(path.string());
  switch (file.status) {
    case TextFile::Status::kOk:
      break;
    case TextFile::Status::kCannotOpen:
    case TextFile::Status::kCannotRead:
      throw ConfigError(
          fmt::format("{}: cannot read: {}", path.string(), std::strerror(file.error_number)));
    case TextFile::Status::kNotRegular:
      throw ConfigError(fmt::format(
          "{}: not a regular file (a FIFO, socket, device or directory): not a pandarcapd "
          "configuration",
          path.string()));
    case TextFile::Status::kTooLarge:
      throw ConfigError(fmt::format("{}:1:1: larger than {} bytes: not a pandarcapd configuration",
                                    path.string(), kMaxOperatorFileBytes));
  }
  return parse_config(file.text, path.string());
}

namespace {

// Sets the one key named `key` from command-line text, with the type and range check the file's
// reader and checker apply to it.
struct TextSetter {
  std::string_view key;
  std::string_view text;
  const Reporter& report;
  bool found = false;

  bool matches(std::string_view table, std::string_view name) {
    if (found || dotted(table, name) != key) return false;
    found = true;
    return true;
  }
  [[noreturn]] void not_a(std::string_view what) const {
    report.fail(key, fmt::format("expected {}, found \"{}\"", what, text));
  }

  void operator()(std::string_view table, std::string_view name, std::string& out,
                  StringCheck check) {
    if (!matches(table, name)) return;
    std::string value(text);
    if (auto problem = check(value)) report.fail(key, *problem);
    out = std::move(value);
  }
  void operator()(std::string_view table, std::string_view name, bool& out, std::monostate) {
    if (!matches(table, name)) return;
    if (text != "true" && text != "false") not_a("true or false");
    out = text == "true";
  }
  template <typename Int>
  void operator()(std::string_view table, std::string_view name, Int& out, IntRange r) {
    if (!matches(table, name)) return;
    std::int64_t v = 0;
    const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), v);
    if (text.empty() || error != std::errc() || end != text.data() + text.size()) {
      not_a("an integer");
    }
    if (v < r.lo || v > r.hi) {
      report.fail(key, fmt::format("{} is out of range ({}..{})", v, r.lo, r.hi));
    }
    out = static_cast<Int>(v);
  }
  void operator()(std::string_view table, std::string_view name, double& out, const RealRange& r) {
    if (!matches(table, name)) return;
    const std::string value(text);
    char* end = nullptr;
    errno = 0;
    const double v = std::strtod(value.c_str(), &end);
    if (value.empty() || end != value.c_str() + value.size() || errno == ERANGE) {
      not_a("a number");
    }
    ValueChecker{report}(table, name, v, r);
    out = v;
  }
};

}  // namespace

void set_config_value(DaemonConfig& config, std::string_view key, std::string_view text,
                      const std::string& source_name) {
  const Reporter report(source_name, nullptr);
  TextSetter setter{key, text, report};
  for_each_key(config, setter);
  if (!setter.found) report.fail(key, "not a configuration key");
}

void validate_config(const DaemonConfig& config, const std::string& source_name) {
  std::vector<Problem> problems;
  check_values(config, Reporter(source_name, nullptr), Positions{}, problems);
  throw_if_any(problems);
}

std::string to_toml(const DaemonConfig& config) {
  std::string out = "# pandarcapd configuration (pandarcapd --print-config)\n";
  std::string_view current_table;
  for_each_key(config, [&](std::string_view table, std::string_view key, const auto& value, auto) {
    if (table != current_table) {
      out += fmt::format("\n[{}]\n", table);
      current_table = table;
    }
    using T = std::decay_t<decltype(value)>;
    if constexpr (std::is_same_v<T, std::string>) {
      out += fmt::format("{} = {}\n", key, toml_string(value));
    } else if constexpr (std::is_same_v<T, bool>) {
      out += fmt::format("{} = {}\n", key, value ? "true" : "false");
    } else if constexpr (std::is_same_v<T, double>) {
      out += fmt::format("{} = {}\n", key, toml_real(value));
    } else {
      out += fmt::format("{} = {}\n", key, value);
    }
  });
  return out;
}

}  // namespace pandarcap
