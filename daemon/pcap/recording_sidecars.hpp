// The files beside a recording that say how to decode it: for
// raw/pandarcap_20261122T120000Z_0001.pcap (or .pcap.zst, or a collision's ..._0001_dup1.pcap, or
// the .part of any of them) they are
//   raw/pandarcap_20261122T120000Z_0001.calibration.csv  the calibration in use
//   (Calibration::to_csv) raw/pandarcap_20261122T120000Z_0001.sensor.json      the same JSON as
//   raw/sensor.json
// The writer puts them there when it finishes a recording; the replay and pandarcap-inspect read
// the calibration back from them. Pure: names only, nothing is opened.
#pragma once

#include <array>
#include <optional>
#include <string>
#include <string_view>

namespace pandarcap {

// A recording's sidecars: its stem + each of these (calibration, then sensor facts).
inline constexpr std::array<std::string_view, 2> kSidecarSuffixes = {".calibration.csv",
                                                                     ".sensor.json"};

struct RecordingSidecars {
  std::string calibration_csv;  // "DIR/STEM.calibration.csv"
  std::string sensor_json;      // "DIR/STEM.sensor.json"
};

// The stem of a recording's file name: the name without its directory and without ".pcap",
// ".pcap.zst", ".pcap.part" or ".pcap.zst.part" ("pandarcap_20261122T120000Z_0001"). Nothing for
// any other name (an MCAP file carries its calibration inside; a .pcapng is not ours), nor for a
// name that is only the extension (".pcap").
std::optional<std::string_view> recording_stem(std::string_view path) noexcept;

// The sidecar paths of the recording at `path`, in the same directory; nothing when
// recording_stem() has none.
std::optional<RecordingSidecars> recording_sidecars(std::string_view path);

}  // namespace pandarcap
