#include "daemon/output/output_names.hpp"

namespace pandarcap {
namespace {

// `name` is `prefix`, `field` '_'-separated fields, a number followed by '_' or '.', ..., `suffix`.
bool named_like(std::string_view name, std::string_view prefix, std::string_view suffix,
                int field) noexcept {
  if (!name.starts_with(prefix) || !name.ends_with(suffix)) return false;
  if (name.size() < prefix.size() + suffix.size() + 1) return false;
  name.remove_prefix(prefix.size());
  name.remove_suffix(suffix.size());
  for (int i = 0; i < field; ++i) {
    const std::size_t underscore = name.find('_');
    if (underscore == std::string_view::npos) return false;
    name.remove_prefix(underscore + 1);
  }
  std::size_t digits = 0;
  while (digits < name.size() && name[digits] >= '0' && name[digits] <= '9')
    ++digits;
  // The number ends the name (before the suffix) or is followed by more fields (_partial, _dupN).
  return digits > 0 && (digits == name.size() || name[digits] == '_');
}

}  // namespace

bool floor_file_is_ours(FloorKind kind, std::string_view name) noexcept {
  switch (kind) {
    case FloorKind::kFrames:
      return named_like(name, "frame_", ".pcd", 0);
    case FloorKind::kRecordings:
      return named_like(name, "pandarcap_", ".pcap", 1) ||
             named_like(name, "pandarcap_", ".pcap.zst", 1);
    case FloorKind::kMcap:
      return named_like(name, "pandarcap_", ".mcap", 1);
    case FloorKind::kNone:
      return false;
  }
  return false;
}

bool upload_file_is_ours(std::string_view name) noexcept {
  const auto digit = [](char c) { return c >= '0' && c <= '9'; };
  // frame_[0-9]*.pcd
  if (name.starts_with("frame_") && name.ends_with(".pcd")) {
    return name.size() > 10 && digit(name[6]);
  }
  // pandarcap_*_[0-9]*.EXT: after the prefix and before ".EXT", an underscore followed by a
  // digit somewhere.
  if (!name.starts_with("pandarcap_")) return false;
  for (const std::string_view extension :
       {std::string_view(".pcap"), std::string_view(".pcap.zst"),
        std::string_view(".calibration.csv"), std::string_view(".sensor.json"),
        std::string_view(".mcap")}) {
    if (!name.ends_with(extension) || name.size() < 10 + extension.size()) continue;
    const std::string_view middle = name.substr(10, name.size() - 10 - extension.size());
    for (std::size_t i = 0; i + 1 < middle.size(); ++i) {
      if (middle[i] == '_' && digit(middle[i + 1])) return true;
    }
  }
  return false;
}

}  // namespace pandarcap
