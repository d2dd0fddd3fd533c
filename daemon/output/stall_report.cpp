#include "daemon/output/stall_report.hpp"

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <sys/stat.h>
#include <unistd.h>

#include <exception>
#include <filesystem>
#include <iterator>
#include <system_error>

#include "core/health/health.hpp"
#include "core/text_encoding.hpp"
#include "core/utc_time.hpp"
#include "daemon/io/file_output.hpp"

namespace pandarcap {

StalledWriterReport::StalledWriterReport(const WriterOptions& options) : options_(options) {}

void StalledWriterReport::write(double stalled_seconds, std::int64_t unix_ns) noexcept {
  if (!options_.prometheus && !options_.jsonl) return;
  const std::string reason = fmt::format(
      "writer stalled for {:.1f} s: its disk does not answer (health directory {}); frames and "
      "recordings wait, the receiver goes on, drops are counted when it is back",
      stalled_seconds, options_.health_dir.string());
  std::string sensor;
  append_label_value(sensor, options_.sensor_name);
  std::string prom;
  const auto out = std::back_inserter(prom);
  fmt::format_to(out,
                 "# HELP pandarcap_state 1 for the daemon's current health state\n"
                 "# TYPE pandarcap_state gauge\n");
  for (std::size_t i = 0; i < kHealthStateCount; ++i) {
    const auto state = static_cast<HealthState>(i);
    fmt::format_to(out, "pandarcap_state{{sensor=\"{}\",state=\"{}\"}} {}\n", sensor,
                   to_string(state), state == HealthState::kDegraded ? 1 : 0);
  }
  fmt::format_to(out,
                 "# HELP pandarcap_health_fallback 1 while the health files are written to "
                 "health.fallback_directory (their own directory cannot be written)\n"
                 "# TYPE pandarcap_health_fallback gauge\n"
                 "pandarcap_health_fallback{{sensor=\"{}\"}} 1\n"
                 "# HELP pandarcap_writer_stalled_seconds Seconds the writer thread has not come "
                 "back from its disk\n"
                 "# TYPE pandarcap_writer_stalled_seconds gauge\n"
                 "pandarcap_writer_stalled_seconds{{sensor=\"{}\"}} {:.1f}\n",
                 sensor, sensor, stalled_seconds);
  std::string line = "{\"time\":\"";
  append_rfc3339(line, unix_ns, 3);
  fmt::format_to(std::back_inserter(line), "\",\"unix_time_ns\":{},\"sensor\":", unix_ns);
  append_json_string(line, options_.sensor_name);
  line += ",\"state\":\"degraded\",\"reason\":";
  append_json_string(line, reason);
  fmt::format_to(std::back_inserter(line),
                 ",\"writer_stalled_seconds\":{:.1f},\"health_fallback\":{{\"active\":true}}}}\n",
                 stalled_seconds);
  for (const std::filesystem::path& dir : options_.health_fallback_dirs) {
    try {
      std::filesystem::create_directories(dir);
      const std::filesystem::path prom_path = dir / options_.prometheus_file.filename();
      if (options_.prometheus) write_file_replacing(prom_path, prom);
      if (options_.jsonl) {
        OutputFile jsonl(dir / "health.jsonl", OutputFile::Mode::kAppend);
        jsonl.write(line);
        jsonl.close();
      }
      struct stat info {};
      prom_path_ = prom_path.native();
      written_inode_ = ::stat(prom_path_.c_str(), &info) == 0 ? info.st_ino : 1;
      if (!logged_) {
        spdlog::error("health: {}; a report of it in {} until the writer is back", reason,
                      dir.string());
        logged_ = true;
      }
      return;
    } catch (const std::exception& error) {
      spdlog::error("health: the writer is stalled and {} cannot take its report: {}", dir.string(),
                    error.what());
    }
  }
}

void StalledWriterReport::clear() noexcept {
  if (written_inode_ == 0) return;
  // The writer renames its own .prom into place (a new inode): that one is left.
  struct stat info {};
  if (::stat(prom_path_.c_str(), &info) == 0 && info.st_ino == written_inode_) {
    ::unlink(prom_path_.c_str());
  }
  spdlog::info("health: the writer is back; its own health files take over again");
  written_inode_ = 0;
  logged_ = false;
}

}  // namespace pandarcap
