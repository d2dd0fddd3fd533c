// Shared helpers for the test suite: locating the real captures and scratch directories.
#pragma once

#include <filesystem>
#include <optional>
#include <string>

namespace pandarcap::test {

// Path of a real capture in ../shared/captures. When the file is missing the test must not pass
// silently in CI: under CI=true this FAILs the test; elsewhere it WARNs and returns nullopt so
// the caller can return early.
std::optional<std::filesystem::path> real_capture(const std::string& name);

// A fresh, empty directory under the system temp dir, removed by the destructor.
class ScratchDir {
 public:
  explicit ScratchDir(const std::string& tag);
  ~ScratchDir();
  ScratchDir(const ScratchDir&) = delete;
  ScratchDir& operator=(const ScratchDir&) = delete;
  const std::filesystem::path& path() const { return path_; }
  std::filesystem::path operator/(const std::string& name) const { return path_ / name; }

 private:
  std::filesystem::path path_;
};

// Path of a built binary (pandarcap-inspect, pandarcapd).
std::filesystem::path binary(const std::string& name);

// Runs a command through /bin/sh, returning its exit status and standard output.
struct CommandResult {
  int exit_code = -1;
  std::string out;
};
CommandResult run_command(const std::string& command);

}  // namespace pandarcap::test
