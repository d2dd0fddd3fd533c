// Reading, checking and printing pandarcapd's TOML configuration (toml++).
//
// Every problem is a ConfigError whose message starts with its location, `file:line:col: `,
// the way compilers report errors, so an operator can jump straight to the key at fault:
//   /etc/pandarcap/pandarcap.toml:12:15: sensor.data_port: 70000 is out of range (1..65535)
// Unknown tables and keys are errors too (a misspelt key must not silently keep its default).
#pragma once

#include <filesystem>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "daemon_config.hpp"

namespace pandarcap {

// Its message holds no control character: a file name, a key or a value with a newline in it
// cannot forge a line of its own (core/log_text.hpp escapes them). A file's problems come one
// line each, joined by newlines.
class ConfigError : public std::runtime_error {
 public:
  explicit ConfigError(const std::string& message);
  // Several problems, one line each (each escaped, then joined).
  static ConfigError lines(const std::vector<std::string>& problems);

 private:
  struct Joined {};
  ConfigError(Joined, const std::string& joined) : std::runtime_error(joined) {}
};

// Parses TOML text. `source_name` is the file name used in messages. Keys that are absent keep
// their defaults. Throws ConfigError for syntax errors, unknown keys, wrong types and values out
// of range (the latter via validate_config).
DaemonConfig parse_config(std::string_view toml_text, const std::string& source_name);

// Reads and parses a file; a missing or unreadable file is a ConfigError naming it.
DaemonConfig load_config_file(const std::filesystem::path& path);

// Checks the values against their ranges and each other (e.g. max_range > min_range, ring slots
// a power of two). Used after command-line overrides, where there is no line to point at: then
// the message starts with `source_name: `.
void validate_config(const DaemonConfig& config, const std::string& source_name);

// Sets one key ("sensor.max_range", "decoder") from its text on a command line ("150", "avx2",
// "true"), with exactly the type and range check a configuration file gets for it: the one
// statement of each key's name, type and range serves the file and every binary's options.
// Throws ConfigError("SOURCE: KEY: problem") for an unknown key, text that is not of the key's
// type, or a value out of range. Checks across keys (max_range > min_range) stay with
// validate_config.
void set_config_value(DaemonConfig& config, std::string_view key, std::string_view text,
                      const std::string& source_name);

// The configuration as a complete TOML document that parse_config reads back to the same values
// (`pandarcapd --print-config`).
std::string to_toml(const DaemonConfig& config);

}  // namespace pandarcap
