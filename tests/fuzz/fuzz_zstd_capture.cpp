// Fuzz target: the zstd-compressed capture reader (a .pcap.zst: daemon/pcap/zstd_read_stream.hpp
// decompressing as libpcap reads). The input is the compressed file; it always starts with the
// zstd magic (prepended when missing), so every run goes through the zstd stream. Any input opens
// or throws CaptureError, and reading ends in kEnd, kTruncated or kError; every yielded payload
// lies inside what a record can hold and agrees with the UDP length it claims.
#include <sys/mman.h>
#include <unistd.h>

#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <string>

#include "daemon/pcap/capture_reader.hpp"
#include "daemon/pcap/zstd_magic.hpp"

using namespace pandarcap;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const int fd = memfd_create("fuzz-zstd-capture", 0);
  if (fd < 0) std::abort();
  std::size_t at = 0;
  if (ftruncate(fd, 0) != 0) std::abort();
  if (size < kZstdMagic.size() || std::memcmp(data, kZstdMagic.data(), kZstdMagic.size()) != 0) {
    if (pwrite(fd, kZstdMagic.data(), kZstdMagic.size(), 0) !=
        static_cast<ssize_t>(kZstdMagic.size())) {
      std::abort();
    }
    at = kZstdMagic.size();
  }
  if (pwrite(fd, data, size, static_cast<off_t>(at)) != static_cast<ssize_t>(size)) std::abort();
  const std::string path = "/proc/self/fd/" + std::to_string(fd);
  try {
    CaptureReader reader(path);
    if (reader.format() != CaptureFormat::kPcapZstd) std::abort();
    CaptureRecord record;
    std::uint64_t yielded = 0;
    CaptureStatus status;
    while ((status = reader.next(record)) == CaptureStatus::kRecord) {
      if (record.payload.size() > record.udp_payload_length && !record.snapped) std::abort();
      if (record.payload.size() > 65535) std::abort();
      ++yielded;
    }
    if (yielded != reader.stats().udp_datagrams) std::abort();
    if (status != CaptureStatus::kEnd && reader.error().empty()) std::abort();
  } catch (const CaptureError&) {
  }
  return 0;
}
