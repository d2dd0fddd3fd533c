// Finishing an MCAP file that a crash (SIGKILL, power loss) or a full disk left open: pandarcapd
// writes mcap/NAME.mcap.part and renames it only after its summary and footer are written, so a
// ".part" found at start-up was never finished. It ends anywhere: inside a chunk, between a chunk
// and its message indexes, inside the tail.
//
// finish_interrupted_mcap() reads the records from the start, checking each (a chunk must
// decompress to its stated size with its stated CRC, and be followed by one whole MessageIndex
// record per channel in it), cuts the file after the last whole record or chunk with its
// indexes (the writer's Padding records are whole records, kept), and writes DataEnd, the summary
// rebuilt from what is kept, the summary offsets and the footer, so that every MCAP reader accepts
// it.
//
// Only a file that begins with the MCAP magic and a Header whose library is pandarcap's is
// touched (`ours`); anything else is left as it is. A file cut within its first records (no
// message kept) is ours with no message: the caller removes it.
#pragma once

#include <cstdint>
#include <string>

namespace pandarcap {

struct McapRecovery {
  bool ours = false;             // when false, nothing was examined or changed (the counts are 0)
  std::uint64_t messages = 0;    // messages kept
  std::uint64_t kept_bytes = 0;  // bytes of the data section kept
  std::uint64_t cut_bytes = 0;   // bytes removed from the end (a cut chunk, an old tail)
};

// Scans `path`, truncates it after its last whole part and appends a tail. Throws
// std::system_error when the file cannot be read or written, and when `path` is a symbolic
// link or not a regular file (never followed).
McapRecovery finish_interrupted_mcap(const std::string& path);

}  // namespace pandarcap
