// Finishing a recording that a crash (SIGKILL, power loss) or a full disk left open: pandarcapd
// writes raw/NAME.pcap.part and renames it only when it closes the file, so a ".part" found at
// start-up is one an earlier run never finished. Its last record may be cut anywhere; everything
// before it is whole. finish_interrupted_pcap() finds the end of the last whole record and cuts
// the file there, so that tcpdump, libpcap and pandarcap-inspect read it to the end.
//
// Only a file that begins with PcapWriter's own global header (pcap_global_header()) is touched;
// anything else is left as it is (`ours` false). A file shorter than the global header
// whose bytes begin that header (an empty one included) is ours, with no record: the process
// died between creating it and writing the header.
#pragma once

#include <cstdint>
#include <string>

namespace pandarcap {

struct PcapRecovery {
  bool ours = false;             // a PcapWriter file: its global header (or the start of it)
  std::uint64_t records = 0;     // whole records kept
  std::uint64_t kept_bytes = 0;  // the file's length now
  std::uint64_t cut_bytes = 0;   // bytes of a cut record (or garbage) removed from the end
};

// Scans `path` and truncates it after its last whole record. Throws std::system_error when the
// file cannot be read or truncated, and when `path` is a symbolic link or not a regular file
// (never followed: the cut must not reach a file elsewhere).
PcapRecovery finish_interrupted_pcap(const std::string& path);

}  // namespace pandarcap
