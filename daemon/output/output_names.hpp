// The names of the daemon's finished files, as the free-space floor, retention and the upload
// backlog recognise them (docs/storage.md, docs/deploy.md). Pure: names only, no file is read.
//
//   frames/  frame_<N>_<UTC>[_partial][_dupN].pcd
//   raw/     pandarcap_<UTC>_<N>[_dupN].pcap and .pcap.zst (a recording), and beside each its
//            sidecars STEM.calibration.csv and STEM.sensor.json (STEM: the recording's name
//            without .pcap / .pcap.zst), which travel and go with it
//   mcap/    pandarcap_<UTC>_<N>[_dupN].mcap
// Never ours: an open file (NAME.part), a temporary (.NAME.tmp) or any hidden file, raw/'s
// calibration.csv, calibration_before_<N>.csv and sensor.json (this run's, rewritten at each
// start), anything else another program put there.
#pragma once

#include <array>
#include <cstdint>
#include <string_view>

namespace pandarcap {

// Which naming an output directory's files follow.
enum class FloorKind : std::uint8_t { kFrames, kRecordings, kMcap, kNone /* free space only */ };

// Whether `name` (a file name, no directory) is one of our finished files in a directory of
// `kind`: frame_<N>_....pcd; pandarcap_<UTC>_<N>....pcap / .pcap.zst; pandarcap_<UTC>_<N>....mcap.
// Sidecars are not: they go with their recording, never on their own.
bool floor_file_is_ours(FloorKind kind, std::string_view name) noexcept;

// Whether `name` is a finished file that leaves by upload from an upload directory: exactly what
// systemd/pandarcap-upload@.service's rclone filter moves (tests/upload/names.txt holds the
// names both are tested on), in any of the upload directories alike:
//   pandarcap_*_[0-9]*.{pcap,pcap.zst,calibration.csv,sensor.json,mcap}   (recordings, sidecars,
//                                                                           MCAP files)
//   frame_[0-9]*.pcd                                                        (frames)
// in rclone's glob (`*` any characters, `[0-9]` a digit). Every file floor_file_is_ours accepts
// is one (the glob is a little wider); never a hidden file or a NAME.part.
bool upload_file_is_ours(std::string_view name) noexcept;

}  // namespace pandarcap
