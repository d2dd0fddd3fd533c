// What earlier runs left in the output directories, dealt with once at start-up, before the
// daemon writes anything.
//
// An interrupted run (a crash, a kill, a power cut) can leave:
//   - raw/*.pcap.part, a recording still open: cut back to its last whole record and renamed to
//     its final name, durably (its data synced before the rename, the directory after), with the
//     sidecars a finished recording has (NAME.calibration.csv, NAME.sensor.json) made from
//     raw/calibration.csv and raw/sensor.json, which still describe the interrupted run here
//     (raw/*.pcap.zst.part: its whole records compressed again into a finished frame,
//     daemon/pcap/pcap_recovery.hpp) (removed if it holds no whole record; a file that is not a
//     pcap of ours, a link or a device is left alone, with a warning);
//   - mcap/*.mcap.part, an MCAP file still open: cut back to its last whole chunk and finished
//     with a summary and footer (daemon/mcap/mcap_recovery.hpp), then renamed the same way;
//   - .NAME.tmp in frames/ and raw/, a file not yet renamed into place: it was never complete,
//     so it is removed (in the health directory, which may be node_exporter's, only the .prom
//     file's own temporary name is);
//   - a last health.jsonl line cut short: dropped, so readers never see two lines glued; and the
//     health directory's writability probe, if a run died between making and removing it.
// Then the finished files of earlier runs are adopted: numbered (the next file continues after
// the highest number found, so names never repeat across restarts) and put on the retention
// lists oldest first, so restarts and crash loops cannot fill the disk.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "daemon/output/output_accounting.hpp"
#include "daemon/output/retention.hpp"

namespace pandarcap {

// Where to look; an empty path: that output is off, nothing of it is touched.
struct OutputLeftovers {
  std::filesystem::path frames_dir, raw_dir, mcap_dir;
  std::vector<std::string> prometheus_temporary_paths;
  std::string jsonl_path, health_probe_path;
};

// Finishes recordings, removes temporaries and drops a cut health line, logging each. Never
// throws for a file it cannot fix (logged, left); a finished recording whose name is taken is
// kept under a "_dupN" name (counted in `accounting`).
void finish_leftovers(const OutputLeftovers& where, OutputAccounting& accounting);

// Earlier runs' frames (frame_<N>_...pcd) / recordings (pandarcap_<UTC>_<N>...pcap and .pcap.zst,
// one list) in `dir`:
// adopted into `retention` oldest first, which is then applied; logged. Returns the next free
// number (0 when there are none).
std::uint64_t adopt_earlier_frames(const std::filesystem::path& dir, Retention& retention);
std::uint64_t adopt_earlier_recordings(const std::filesystem::path& dir, Retention& retention);
// The same for MCAP files (pandarcap_<UTC>_<N>...mcap).
std::uint64_t adopt_earlier_mcap_files(const std::filesystem::path& dir, Retention& retention);

}  // namespace pandarcap
