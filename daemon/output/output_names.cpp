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

std::string_view recording_stem(std::string_view name) noexcept {
  for (const std::string_view suffix : {std::string_view(".pcap"), std::string_view(".pcap.zst")}) {
    if (named_like(name, "pandarcap_", suffix, 1))
      return name.substr(0, name.size() - suffix.size());
  }
  return {};
}

bool upload_file_is_ours(FloorKind kind, std::string_view name) noexcept {
  if (floor_file_is_ours(kind, name)) return true;
  if (kind != FloorKind::kRecordings) return false;
  for (const std::string_view suffix : kSidecarSuffixes) {
    if (named_like(name, "pandarcap_", suffix, 1)) return true;
  }
  return false;
}

}  // namespace pandarcap
