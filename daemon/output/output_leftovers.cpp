#include "daemon/output/output_leftovers.hpp"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <fstream>
#include <iterator>
#include <optional>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

#include "daemon/io/file_output.hpp"
#include "daemon/mcap/mcap_recovery.hpp"
#include "daemon/pcap/pcap_recovery.hpp"
#include "daemon/pcap/recording_sidecars.hpp"

namespace pandarcap {
namespace {

namespace fs = std::filesystem;

// The number in one of our file names: the `field`-th '_'-separated field after `prefix`
// ("frame_000123_...pcd": field 0; "pandarcap_20261122T120000Z_0007...pcap": field 1). Nothing
// when the name is not one of ours.
std::optional<std::uint64_t> number_in_name(std::string_view name, std::string_view prefix,
                                            std::string_view suffix, int field) {
  if (!name.starts_with(prefix) || !name.ends_with(suffix)) return std::nullopt;
  name.remove_prefix(prefix.size());
  for (int i = 0; i < field; ++i) {
    const std::size_t underscore = name.find('_');
    if (underscore == std::string_view::npos) return std::nullopt;
    name.remove_prefix(underscore + 1);
  }
  std::uint64_t number = 0;
  std::size_t digits = 0;
  while (digits < name.size() && name[digits] >= '0' && name[digits] <= '9') {
    if (digits == 18) return std::nullopt;  // not one of ours, and beyond what a count reaches
    number = number * 10 + static_cast<std::uint64_t>(name[digits] - '0');
    ++digits;
  }
  if (digits == 0 || (digits < name.size() && name[digits] != '_' && name[digits] != '.')) {
    return std::nullopt;
  }
  return number;
}

// What finishing one kind of recording found: whether it is ours, how many whole records
// (packets, messages) it keeps, and how many bytes were cut.
struct Finished {
  bool ours = false;
  std::uint64_t records = 0, cut_bytes = 0;
};

Finished finish_pcap(const std::string& part) {
  const PcapRecovery r = finish_interrupted_pcap(part);
  return {r.ours, r.records, r.cut_bytes};
}

Finished finish_pcap_zst(const std::string& part) {
  const PcapRecovery r = finish_interrupted_pcap_zst(part);
  return {r.ours, r.records, r.cut_bytes};
}

Finished finish_mcap(const std::string& part) {
  const McapRecovery r = finish_interrupted_mcap(part);
  return {r.ours, r.messages, r.cut_bytes};
}

// A finished recording's sidecars (pcap_recorder.hpp), for one an interrupted run left: its
// directory's calibration.csv and sensor.json, which this start has not replaced yet, as
// NAME.calibration.csv and NAME.sensor.json; durable, and never over a file of that name.
void write_recovered_sidecars(const fs::path& dir, const std::string& recording) {
  const std::optional<RecordingSidecars> sidecars = recording_sidecars(recording);
  if (!sidecars) return;
  for (const auto& [source, to] : {std::pair{"calibration.csv", &sidecars->calibration_csv},
                                   std::pair{"sensor.json", &sidecars->sensor_json}}) {
    const fs::path from = dir / source;
    std::error_code ec;
    if (fs::exists(*to, ec) || !fs::is_regular_file(from, ec) || fs::file_size(from, ec) == 0) {
      continue;
    }
    try {
      std::ifstream in(from, std::ios::binary);
      const std::string text((std::istreambuf_iterator<char>(in)),
                             std::istreambuf_iterator<char>());
      write_file_durably(*to, text);
    } catch (const std::exception& error) {
      spdlog::warn("{}: cannot write its sidecar {}: {}", recording, *to, error.what());
    }
  }
}

// Recordings left open (NAME`suffix`.part): cut back to their last whole part, finished and
// given their final name.
void finish_interrupted_recordings(const fs::path& dir, std::string_view suffix,
                                   Finished (*finish)(const std::string&),
                                   OutputAccounting& accounting, bool sidecars) {
  const std::string part_suffix = std::string(suffix) + ".part";
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(dir, ec)) {
    const std::string part = entry.path().native();
    if (!part.ends_with(part_suffix)) continue;
    // Never followed: a link (or a device, a FIFO) here points at a file that is not ours to
    // cut, wherever it leads.
    if (entry.is_symlink(ec) || !entry.is_regular_file(ec)) {
      spdlog::warn("{}: not a regular file; left as it is", part);
      continue;
    }
    try {
      const Finished recovered = finish(part);
      if (!recovered.ours) {
        spdlog::warn("{}: not a recording of ours; left as it is", part);
        continue;
      }
      if (recovered.records == 0) {
        fs::remove(part);
        spdlog::warn("{}: left by an interrupted run with no whole record; removed", part);
        continue;
      }
      // Its final name chosen first (a taken one becomes "_dupN", as place_without_replacing
      // makes it), so that the sidecars written for it are in place before it is.
      std::string finished = part.substr(0, part.size() - 5);  // without ".part"
      const std::string wanted = finished;
      if (fs::exists(finished, ec)) {
        const std::size_t extension = finished.size() - suffix.size();
        for (unsigned n = 1; fs::exists(finished, ec); ++n)
          finished = fmt::format("{}_dup{}{}", wanted.substr(0, extension), n, suffix);
      }
      if (sidecars) write_recovered_sidecars(dir, finished);
      if (place_durably(part, finished) || finished != wanted) {
        accounting.name_collision(part, finished);
      }
      spdlog::warn(
          "{}: left by an interrupted run; finished as {} ({} whole records, {} bytes of "
          "a cut record removed)",
          part, fs::path(finished).filename().string(), recovered.records, recovered.cut_bytes);
    } catch (const std::exception& error) {
      spdlog::error("{}: cannot finish a recording left by an interrupted run: {}", part,
                    error.what());
    }
  }
}

// Temporary files (".NAME.tmp") hold nothing that was ever complete: removed.
void remove_temporaries(const fs::path& dir) {
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(dir, ec)) {
    const std::string name = entry.path().filename().native();
    if (name.size() > 5 && name.front() == '.' && name.ends_with(".tmp") &&
        entry.is_regular_file(ec)) {
      fs::remove(entry.path(), ec);
      spdlog::info("{}: temporary file of an interrupted run removed", entry.path().string());
    }
  }
}

// A health line cut short (a crash mid-append, a full disk) is dropped: readers then never see
// two lines glued together.
void drop_cut_health_line(const std::string& jsonl_path) {
  std::ifstream in(jsonl_path, std::ios::binary | std::ios::ate);
  const std::streamoff size = in ? static_cast<std::streamoff>(in.tellg()) : 0;
  if (size <= 0) return;
  std::streamoff keep = size;
  char c = 0;
  while (keep > 0) {
    in.seekg(keep - 1);
    in.get(c);
    if (c == '\n') break;
    --keep;
  }
  if (keep < size) {
    std::error_code ec;
    fs::resize_file(jsonl_path, static_cast<std::uintmax_t>(keep), ec);
    spdlog::warn("{}: a line cut short by an interrupted run removed ({} bytes)", jsonl_path,
                 size - keep);
  }
}

struct Found {
  std::uint64_t number;
  std::string name;
  fs::path path;
  std::uint64_t bytes;
};

bool oldest_first(const Found& a, const Found& b) {
  return a.number != b.number ? a.number < b.number : a.name < b.name;
}

// Our files in `dir`, oldest (lowest number) first; a link or anything not a regular file is not
// ours.
std::vector<Found> scan(const fs::path& dir, std::string_view prefix, std::string_view suffix,
                        int field) {
  std::vector<Found> found;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(dir, ec)) {
    const std::string name = entry.path().filename().native();
    const auto number = number_in_name(name, prefix, suffix, field);
    if (!number || entry.is_symlink(ec) || !entry.is_regular_file(ec)) continue;
    const auto bytes = entry.file_size(ec);
    found.push_back({*number, name, entry.path(), ec ? 0 : bytes});
  }
  std::sort(found.begin(), found.end(), oldest_first);
  return found;
}

std::uint64_t adopt(const fs::path& dir, std::string_view prefix, std::string_view suffix,
                    int field, Retention& retention, const char* what,
                    std::string_view other_suffix = {}) {
  std::vector<Found> found = scan(dir, prefix, suffix, field);
  if (!other_suffix.empty()) {
    // Both kinds in one list, oldest first: retention and the numbering span them.
    std::vector<Found> other = scan(dir, prefix, other_suffix, field);
    std::vector<Found> both;
    both.reserve(found.size() + other.size());
    std::merge(std::make_move_iterator(found.begin()), std::make_move_iterator(found.end()),
               std::make_move_iterator(other.begin()), std::make_move_iterator(other.end()),
               std::back_inserter(both), oldest_first);
    found = std::move(both);
  }
  if (found.empty()) return 0;
  for (const Found& f : found)
    retention.adopt(f.path.native(), f.bytes);
  const std::size_t removed = retention.enforce();
  spdlog::info(
      "{}: {} {} of earlier runs{}", dir.string(), found.size(), what,
      removed != 0 ? fmt::format("; retention removed the oldest {}", removed) : std::string());
  return found.back().number + 1;
}

}  // namespace

void finish_leftovers(const OutputLeftovers& where, OutputAccounting& accounting) {
  if (!where.raw_dir.empty()) {
    finish_interrupted_recordings(where.raw_dir, ".pcap", &finish_pcap, accounting, true);
    finish_interrupted_recordings(where.raw_dir, ".pcap.zst", &finish_pcap_zst, accounting, true);
  }
  if (!where.mcap_dir.empty()) {
    // An MCAP file carries its calibration inside (an attachment).
    finish_interrupted_recordings(where.mcap_dir, ".mcap", &finish_mcap, accounting, false);
  }
  if (!where.frames_dir.empty()) remove_temporaries(where.frames_dir);
  if (!where.raw_dir.empty()) remove_temporaries(where.raw_dir);
  // The health directory may be shared (node_exporter's): only our own temporary name.
  std::error_code ec;
  for (const std::string& temporary : where.prometheus_temporary_paths) {
    if (fs::remove(temporary, ec)) {
      spdlog::info("{}: temporary file of an interrupted run removed", temporary);
    }
  }
  if (!where.health_probe_path.empty() && fs::remove(where.health_probe_path, ec)) {
    spdlog::info("{}: writability probe of an interrupted run removed", where.health_probe_path);
  }
  if (!where.jsonl_path.empty()) drop_cut_health_line(where.jsonl_path);
}

std::uint64_t adopt_earlier_frames(const fs::path& dir, Retention& retention) {
  return adopt(dir, "frame_", ".pcd", 0, retention, "frames");
}

std::uint64_t adopt_earlier_recordings(const fs::path& dir, Retention& retention) {
  return adopt(dir, "pandarcap_", ".pcap", 1, retention, "recordings", ".pcap.zst");
}

std::uint64_t adopt_earlier_mcap_files(const fs::path& dir, Retention& retention) {
  return adopt(dir, "pandarcap_", ".mcap", 1, retention, "MCAP files");
}

}  // namespace pandarcap
