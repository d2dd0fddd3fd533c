// How configuration problems are found and reported: each at its `file:line:col` when the key
// came from a file, all of a file's problems at once in the file's order; the range check of
// each key and the checks between keys (max_range > min_range, ring slots a power of two).
// Internal to config/.
#pragma once

#include <toml++/toml.h>

#include <functional>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include "config/config_keys.hpp"
#include "config/config_loader.hpp"
#include "config/daemon_config.hpp"

namespace pandarcap::config_detail {

// Where each key was found, so value checks can point at the line.
using Positions = std::map<std::string, toml::source_position, std::less<>>;

// Builds "where: key: message" with `where` the key's position if known, else the source name.
class Reporter {
 public:
  Reporter(const std::string& source_name, const Positions* positions)
      : source_(source_name), positions_(positions) {}

  [[noreturn]] void fail(std::string_view key, const std::string& message) const {
    if (positions_ != nullptr) {
      if (auto it = positions_->find(key); it != positions_->end()) {
        fail_at(it->second, key, message);
      }
    }
    throw ConfigError(fmt::format("{}: {}: {}", source_, key, message));
  }

  [[noreturn]] void fail_at(const toml::source_position& at, std::string_view key,
                            const std::string& message) const {
    throw ConfigError(fmt::format("{}:{}:{}: {}: {}", source_, at.line, at.column, key, message));
  }

 private:
  const std::string& source_;
  const Positions* positions_;
};

// Range checks of single values (the file reader has already checked the types).
struct ValueChecker {
  const Reporter& report;

  void operator()(std::string_view table, std::string_view key, const std::string& value,
                  StringCheck check) const {
    if (auto problem = check(value)) report.fail(dotted(table, key), *problem);
  }
  void operator()(std::string_view, std::string_view, bool, std::monostate) const {}
  template <typename Int>
  void operator()(std::string_view table, std::string_view key, Int value, IntRange r) const {
    const auto v = static_cast<long double>(value);
    if (v < static_cast<long double>(r.lo) || v > static_cast<long double>(r.hi)) {
      report.fail(dotted(table, key),
                  fmt::format("{} is out of range ({}..{})", value, r.lo, r.hi));
    }
  }
  void operator()(std::string_view table, std::string_view key, double value,
                  const RealRange& r) const {
    if (!in_range(value, r)) {
      report.fail(dotted(table, key), fmt::format("{} is out of range ({}{})", value, describe(r),
                                                  std::isfinite(value) ? "" : ", finite"));
    }
  }
};

// One problem found in a file: where (for the order they are reported in) and its whole text.
struct Problem {
  toml::source_position at;
  std::string text;
};

// Runs `check`, which reports through a throwing Reporter, and keeps what it throws: a file's
// problems are reported all at once, in the order of the file, not one per run.
template <typename Check>
void collect(std::vector<Problem>& problems, const Positions& positions, std::string_view key,
             Check&& check) {
  try {
    check();
  } catch (const ConfigError& error) {
    const auto it = positions.find(key);
    problems.push_back(
        Problem{it != positions.end() ? it->second : toml::source_position{}, error.what()});
  }
}

// Every value check (each key's range, then the checks between keys), all problems kept.
void check_values(const DaemonConfig& c, const Reporter& report, const Positions& positions,
                  std::vector<Problem>& problems);

// All the problems of a file at once, in the file's order, one per line: throws ConfigError
// when there is any.
void throw_if_any(std::vector<Problem>& problems);

}  // namespace pandarcap::config_detail
