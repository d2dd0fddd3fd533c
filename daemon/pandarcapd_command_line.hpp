// pandarcapd's command line: what it asks for (a check, a print, a run) and the configuration
// keys it sets, in the order given. Usage errors end the process here, with one line on stderr
// and exit status 64 (CliArgs); --help and --version print and exit 0.
#pragma once

#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "daemon/run_source.hpp"

namespace pandarcap {

struct CommandLine {
  std::optional<std::string> config_path;
  bool check_config = false;
  bool print_config = false;
  bool print_calibration = false;
  bool allow_root = false;
  RunSource source;
  std::optional<double> duration_s;
  // Keys set on the command line, applied to the configuration in the order given.
  std::vector<std::pair<std::string_view, std::string>> overrides;
};

// Parses argv. Option values with a configuration key are checked against the key's type and
// range here (config/command_line.hpp); checks across keys wait for the whole configuration.
CommandLine parse_command_line(int argc, char** argv);

}  // namespace pandarcap
