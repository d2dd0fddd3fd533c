#include "daemon/output/output_directories.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <system_error>

#include "daemon/io/errors.hpp"
#include "daemon/output/health_room.hpp"
#include "daemon/output/space_floor.hpp"

namespace pandarcap {
namespace {

namespace fs = std::filesystem;

// Whether this process (its effective ids, as the daemon will run) may create entries in `dir`.
bool writable_directory(const fs::path& dir) {
  return ::faccessat(AT_FDCWD, dir.c_str(), W_OK | X_OK, AT_EACCESS) == 0;
}

// The problem with writing into `dir` (created when missing), or "".
std::string directory_problem(const fs::path& dir) {
  // The deepest part of the path that exists decides: a directory we may write into, or not.
  fs::path existing = fs::absolute(dir).lexically_normal();
  std::error_code ec;
  while (!fs::exists(existing, ec) && existing.has_relative_path()) {
    existing = existing.parent_path();
  }
  if (!fs::is_directory(existing, ec)) {
    return fmt::format("'{}' is not a directory", existing.string());
  }
  if (!writable_directory(existing)) {
    return fmt::format("'{}' is not writable by uid {}", existing.string(), ::geteuid());
  }
  return {};
}

}  // namespace

std::vector<std::string> output_problems(const WriterOptions& o) {
  std::vector<std::string> problems;
  std::vector<std::string> seen;  // one line per cause: frames/ and raw/ share the output's
  const auto check = [&](const char* what, const fs::path& dir) {
    const std::string problem = directory_problem(dir);
    if (problem.empty() || std::find(seen.begin(), seen.end(), problem) != seen.end()) return;
    seen.push_back(problem);
    problems.push_back(fmt::format("{} '{}': {}", what, dir.string(), problem));
  };
  check("output directory", o.output_dir);
  if (o.frames) check("frames directory", o.output_dir / "frames");
  if (o.pcap) check("recording directory", o.output_dir / "raw");
  if (o.mcap) check("MCAP directory", o.output_dir / "mcap");
  if (o.jsonl) {
    check("health directory", o.health_dir);
    const fs::path jsonl = o.health_dir / "health.jsonl";
    std::error_code ec;
    if (fs::exists(jsonl, ec) && ::faccessat(AT_FDCWD, jsonl.c_str(), W_OK, AT_EACCESS) != 0) {
      problems.push_back(
          fmt::format("health file '{}': not writable by uid {}", jsonl.string(), ::geteuid()));
    }
  }
  if (o.prometheus) {
    check("textfile directory",
          o.prometheus_file.has_parent_path() ? o.prometheus_file.parent_path() : fs::path("."));
  }
  return problems;
}

OutputDirectoryLock::OutputDirectoryLock(const fs::path& directory) {
  fs::create_directories(directory);
  const fs::path path = directory / "pandarcapd.lock";
  fd_.reset(::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC | O_NOFOLLOW, 0644));
  if (!fd_) io::throw_errno("cannot open", path.native());
  if (::flock(fd_.get(), LOCK_EX | LOCK_NB) != 0) {
    const int error = errno;
    char pid[32] = {};
    const ssize_t n = ::pread(fd_.get(), pid, sizeof pid - 1, 0);
    fd_.reset();
    if (error == EWOULDBLOCK) {
      std::string holder(pid, n > 0 ? static_cast<std::size_t>(n) : 0);
      while (!holder.empty() && (holder.back() == '\n' || holder.back() == ' '))
        holder.pop_back();
      throw OutputDirectoryBusy(fmt::format(
          "another pandarcapd{} is writing to '{}' (it holds {}): two daemons must not share an "
          "output directory; give each its own output.directory",
          holder.empty() ? "" : " (pid " + holder + ")", directory.string(), path.string()));
    }
    io::throw_error(error, "cannot lock", path.native());
  }
  // Ours now: the pid is for the message a second daemon prints.
  const std::string pid = fmt::format("{}\n", ::getpid());
  if (::ftruncate(fd_.get(), 0) != 0 ||
      ::pwrite(fd_.get(), pid.data(), pid.size(), 0) != static_cast<ssize_t>(pid.size())) {
    // The lock holds without the pid; only the message would lack it.
  }
}

namespace {

// Each output directory's file system once (the first directory on it names it): `check(what,
// directory)`. The nearest existing directory tells the file system (the rest is made at start).
template <typename Check>
void for_each_output_file_system(const WriterOptions& o, Check&& check) {
  std::vector<dev_t> seen;
  const auto once = [&](const char* what, const fs::path& dir) {
    fs::path at = dir;
    struct stat info {};
    while (::stat(at.c_str(), &info) != 0 && at.has_parent_path() && at.parent_path() != at)
      at = at.parent_path();
    if (std::find(seen.begin(), seen.end(), info.st_dev) != seen.end()) return;
    seen.push_back(info.st_dev);
    check(what, dir);
  };
  if (o.frames) once("frames directory", o.output_dir / "frames");
  if (o.pcap) once("recording directory", o.output_dir / "raw");
  if (o.mcap) once("MCAP directory", o.output_dir / "mcap");
  if (o.jsonl || o.prometheus) once("health directory", o.health_dir);
  if (o.prometheus && o.prometheus_file.has_parent_path())
    once("textfile directory", o.prometheus_file.parent_path());
}

}  // namespace

std::vector<std::string> space_problems(const WriterOptions& o, std::vector<std::string>& report) {
  std::vector<std::string> problems;
  const std::uint64_t needed = kOutputFloorBytes + kHealthReserveBytes;
  for_each_output_file_system(o, [&](const char* what, const fs::path& dir) {
    const auto free = free_bytes_at(dir);
    if (!free) return;
    const std::string line = fmt::format("{} '{}': {} MiB free, {} MiB needed", what, dir.string(),
                                         *free >> 20, needed >> 20);
    report.push_back(line);
    if (*free < needed) problems.push_back(line + " (the rest is kept for the health files)");
  });
  return problems;
}

std::vector<std::string> health_fallback_report(const WriterOptions& o) {
  std::vector<std::string> lines;
  if (!o.jsonl && !o.prometheus) return lines;
  for (const fs::path& dir : o.health_fallback_dirs) {
    const std::string problem = directory_problem(dir);
    lines.push_back(problem.empty()
                        ? fmt::format("'{}' (made when first needed)", dir.string())
                        : fmt::format("'{}' cannot be used: {}", dir.string(), problem));
    if (problem.empty()) break;  // the ones after are not reached
  }
  return lines;
}

std::vector<std::string> floor_report(const WriterOptions& o) {
  std::vector<std::string> lines;
  const bool any_output = o.frames || o.pcap || o.mcap;
  if (!any_output) return lines;
  if (o.min_free_bytes == 0 && o.min_free_percent <= 0) {
    lines.push_back(
        "none (output.min_free_bytes and min_free_percent 0): nothing of pandarcap's is removed "
        "for space; a disk its own files fill refuses writes, counted");
    return lines;
  }
  WriterOptions outputs = o;  // the health directory holds none of the floor's files
  outputs.jsonl = outputs.prometheus = false;
  for_each_output_file_system(outputs, [&](const char* what, const fs::path& dir) {
    const auto space = file_system_space_at(dir);
    if (!space) return;
    const auto percent =
        static_cast<std::uint64_t>(static_cast<double>(space->size) * o.min_free_percent / 100.0);
    const std::uint64_t configured = std::max(o.min_free_bytes, percent);
    const std::uint64_t minimum = minimum_floor_bytes(kOutputFloorBytes, 0);
    if (configured >= minimum) {
      lines.push_back(fmt::format(
          "{} '{}': {} MiB (output.min_free_bytes / min_free_percent), at least the {} MiB kept "
          "for the health files plus 2 s of writing at the measured rate",
          what, dir.string(), configured >> 20, kOutputFloorBytes >> 20));
    } else {
      lines.push_back(fmt::format(
          "{} '{}': output.min_free_bytes / min_free_percent ({} MiB) is below the {} MiB kept "
          "for the health files plus 2 s of writing: raised to that ({} MiB at the start, then "
          "with the measured write rate)",
          what, dir.string(), configured >> 20, kOutputFloorBytes >> 20, minimum >> 20));
    }
  });
  return lines;
}

bool make_again_if_removed(const std::filesystem::path& directory) noexcept {
  std::error_code error;
  if (std::filesystem::is_directory(directory, error)) return false;
  std::filesystem::create_directories(directory, error);
  if (error) return false;
  spdlog::warn("{} was removed while running: made again", directory.string());
  return true;
}

io::IoError open_in_directory(OutputFile& file, std::string_view path, OutputFile::Mode mode,
                              const std::filesystem::path& directory) {
  const io::IoError error = file.try_open(path, mode);
  if (error.code != ENOENT || !make_again_if_removed(directory)) return error;
  return file.try_open(path, mode);
}

}  // namespace pandarcap
