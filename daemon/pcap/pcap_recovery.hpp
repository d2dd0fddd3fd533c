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
#include <optional>
#include <string>

namespace pandarcap {

struct PcapRecovery {
  bool ours = false;             // a PcapWriter file: its global header (or the start of it)
  std::uint64_t records = 0;     // whole records kept
  std::uint64_t kept_bytes = 0;  // the file's length now
  std::uint64_t cut_bytes = 0;   // bytes of a cut record (or garbage) removed from the end
};

// The bytes a PcapWriter record holds after its 16-byte header `record_header`, or nothing when
// the header cannot be one of ours (more than the snap length, or more captured than the
// datagram had: a cut datagram is recorded with fewer captured than original bytes, never more).
// Where a recovery finds one, the good part of the file ends.
std::optional<std::uint32_t> pcap_record_captured_bytes(const std::uint8_t* record_header) noexcept;

// Scans `path` and truncates it after its last whole record. Throws std::system_error when the
// file cannot be read or truncated, and when `path` is a symbolic link or not a regular file
// (never followed: the cut must not reach a file elsewhere).
PcapRecovery finish_interrupted_pcap(const std::string& path);

// The same for a compressed recording (NAME.pcap.zst.part, PcapWriter with a compressor), whose
// zstd frame a killed run left unfinished. It is decompressed as far as it goes (a cut or corrupt
// block ends it), and its whole records are compressed again into one finished frame, written
// beside it as a temporary (.NAME.tmp) that then replaces it: every record a flush reached is
// kept, and tshark reads the result. Ours: a file whose stream begins with pcap_global_header()
// (or the start of it), or, decompressing to nothing, one that begins as a zstd frame does.
// kept_bytes is the finished file's size; cut_bytes counts pcap stream bytes dropped (a record
// cut short, or garbage). With no whole record the file is left for the caller to remove.
PcapRecovery finish_interrupted_pcap_zst(const std::string& path);

}  // namespace pandarcap
