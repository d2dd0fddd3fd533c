// A small command-line reader shared by the binaries: walks argv, takes option values, and turns
// every mistake into one line on stderr plus exit status 64 (EX_USAGE). `-h`/`--help` print the
// usage text and `--version` the program's name and version, and exit 0.
#pragma once

#include <fmt/format.h>

#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <string_view>
#include <vector>

#include "config/suggest.hpp"
#include "core/log_text.hpp"

namespace pandarcap {

class CliArgs {
 public:
  CliArgs(int argc, char** argv, std::string_view usage)
      : argc_(argc), argv_(argv), usage_(usage), program_(argc > 0 ? argv[0] : "pandarcap") {
    if (const auto slash = program_.rfind('/'); slash != std::string_view::npos) {
      program_.remove_prefix(slash + 1);
    }
  }

  bool more() const { return index_ < argc_; }

  // The next argument; handles --help and --version itself.
  std::string_view next() {
    std::string_view arg = argv_[index_++];
    if (arg == "-h" || arg == "--help") {
      std::fwrite(usage_.data(), 1, usage_.size(), stdout);
      std::exit(0);
    }
    if (arg == "--version") {
      std::printf("%.*s %s\n", static_cast<int>(program_.size()), program_.data(),
                  PANDARCAP_VERSION);
      std::exit(0);
    }
    return arg;
  }

  std::string_view value(std::string_view option) {
    if (!more()) usage_error(fmt::format("{} needs a value", option));
    return argv_[index_++];
  }

  long long integer(std::string_view option, long long min, long long max) {
    const std::string_view text = value(option);
    long long result = 0;
    const auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), result);
    if (ec != std::errc() || ptr != text.data() + text.size() || result < min || result > max) {
      usage_error(
          fmt::format("{} takes a whole number from {} to {}, got '{}'", option, min, max, text));
    }
    return result;
  }

  double number(std::string_view option, double min, double max) {
    const std::string_view text = value(option);
    double result = 0;
    const auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), result);
    if (ec != std::errc() || ptr != text.data() + text.size() || !std::isfinite(result) ||
        result < min || result > max) {
      usage_error(fmt::format("{} takes a number from {} to {}, got '{}'", option, min, max, text));
    }
    return result;
  }

  // An argument that is no option of this program: said so, with the option the usage text
  // lists that it most likely meant ("unknown option '--outptu-dir' (did you mean
  // --output-dir?)").
  [[noreturn]] void unknown_option(std::string_view arg) const {
    std::vector<std::string_view> options;
    for (std::size_t at = usage_.find("--"); at != std::string_view::npos;
         at = usage_.find("--", at + 2)) {
      if (at > 0 && usage_[at - 1] != ' ' && usage_[at - 1] != '[' && usage_[at - 1] != '|')
        continue;
      std::size_t end = at + 2;
      while (end < usage_.size() &&
             (std::isalnum(static_cast<unsigned char>(usage_[end])) != 0 || usage_[end] == '-'))
        ++end;
      if (end > at + 2) options.push_back(usage_.substr(at, end - at));
    }
    if (const auto near = nearest(arg, options)) {
      usage_error(fmt::format("unknown option '{}' (did you mean {}?)", arg, *near));
    }
    usage_error(fmt::format("unknown option '{}'", arg));
  }

  [[noreturn]] void usage_error(const std::string& message) const {
    // The message quotes the command line, which may hold control characters: escaped.
    std::fprintf(stderr, "%.*s: %s\nTry '%.*s --help'.\n", static_cast<int>(program_.size()),
                 program_.data(), escaped_control(message).c_str(),
                 static_cast<int>(program_.size()), program_.data());
    std::exit(64);
  }

 private:
  int argc_;
  char** argv_;
  std::string_view usage_;
  std::string_view program_;
  int index_ = 1;
};

}  // namespace pandarcap
