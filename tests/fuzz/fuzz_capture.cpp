// Fuzz target: the capture-file reader (libpcap for the file formats, our own link-layer, IPv4
// and UDP parsing). The input is the whole file, handed over through an in-memory file. Any
// input opens or throws CaptureError, and reading ends in kEnd, kTruncated or kError; every
// yielded payload lies inside the record and agrees with the UDP length it claims.
#include <sys/mman.h>
#include <unistd.h>

#include <cstdint>
#include <cstdlib>
#include <string>

#include "daemon/pcap/capture_reader.hpp"

using namespace pandarcap;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const int fd = memfd_create("fuzz-capture", 0);
  if (fd < 0) std::abort();
  if (ftruncate(fd, 0) != 0 || pwrite(fd, data, size, 0) != static_cast<ssize_t>(size)) {
    std::abort();
  }
  const std::string path = "/proc/self/fd/" + std::to_string(fd);
  try {
    CaptureReader reader(path);
    CaptureRecord record;
    std::uint64_t yielded = 0;
    while (reader.next(record) == CaptureStatus::kRecord) {
      if (record.payload.size() > record.udp_payload_length && !record.snapped) std::abort();
      if (record.payload.size() > size) std::abort();
      ++yielded;
    }
    if (yielded != reader.stats().udp_datagrams) std::abort();
  } catch (const CaptureError&) {
  }
  return 0;
}
