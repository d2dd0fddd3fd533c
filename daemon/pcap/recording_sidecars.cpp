#include "daemon/pcap/recording_sidecars.hpp"

#include <array>

namespace pandarcap {

std::optional<std::string_view> recording_stem(std::string_view path) noexcept {
  const std::size_t slash = path.rfind('/');
  const std::string_view name = slash == std::string_view::npos ? path : path.substr(slash + 1);
  // The longest first: ".pcap.zst.part" before ".pcap.part" is never ambiguous, but ".pcap" must
  // come last so that "x.pcap.zst" is not read as a stem "x.pcap.zst" minus nothing.
  static constexpr std::array<std::string_view, 4> kExtensions = {".pcap.zst.part", ".pcap.part",
                                                                  ".pcap.zst", ".pcap"};
  for (const std::string_view extension : kExtensions) {
    if (name.size() > extension.size() && name.ends_with(extension))
      return name.substr(0, name.size() - extension.size());
  }
  return std::nullopt;
}

std::optional<RecordingSidecars> recording_sidecars(std::string_view path) {
  const std::optional<std::string_view> stem = recording_stem(path);
  if (!stem) return std::nullopt;
  const std::size_t slash = path.rfind('/');
  const std::string directory(slash == std::string_view::npos ? std::string_view{}
                                                              : path.substr(0, slash + 1));
  const std::string base = directory + std::string(*stem);
  return RecordingSidecars{base + std::string(kSidecarSuffixes[0]),
                           base + std::string(kSidecarSuffixes[1])};
}

}  // namespace pandarcap
