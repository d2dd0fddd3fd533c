// Fuzz target: the MCAP packet reader (daemon/pcap/mcap_packet_reader.hpp, through CaptureReader
// as the replay and pandarcap-inspect use it): record lengths, schemas and channels, chunks
// (zstd frames, sizes, CRCs), message records inside and outside chunks, PandarPacket CDR. The
// input is the whole file; it always starts with the MCAP magic (prepended when missing). Any
// input opens or throws CaptureError (no packets, or none readable before a failure), and reading
// ends in kEnd, kTruncated or kError; every yielded payload lies inside the file's bytes once
// decompressed (at most a chunk's size) and has no addresses.
#include <sys/mman.h>
#include <unistd.h>

#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <string>

#include "core/mcap/mcap_records.hpp"
#include "daemon/pcap/capture_reader.hpp"
#include "daemon/pcap/mcap_packet_reader.hpp"

using namespace pandarcap;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const int fd = memfd_create("fuzz-mcap-packets", 0);
  if (fd < 0) std::abort();
  const auto& magic = mcap::kMagic;
  std::size_t at = 0;
  if (ftruncate(fd, 0) != 0) std::abort();
  if (size < magic.size() || std::memcmp(data, magic.data(), magic.size()) != 0) {
    if (pwrite(fd, magic.data(), magic.size(), 0) != static_cast<ssize_t>(magic.size())) {
      std::abort();
    }
    at = magic.size();
  }
  if (pwrite(fd, data, size, static_cast<off_t>(at)) != static_cast<ssize_t>(size)) std::abort();
  const std::string path = "/proc/self/fd/" + std::to_string(fd);
  try {
    CaptureReader reader(path);
    if (reader.format() != CaptureFormat::kMcap || reader.has_endpoints()) std::abort();
    CaptureRecord record;
    std::uint64_t yielded = 0;
    CaptureStatus status;
    while ((status = reader.next(record)) == CaptureStatus::kRecord) {
      if (record.payload.size() != record.udp_payload_length || record.snapped) std::abort();
      if (record.payload.size() > kMaxChunkBytes) std::abort();
      if (record.source.port != 0 || record.destination.ip != 0) std::abort();
      ++yielded;
    }
    const CaptureStats& stats = reader.stats();
    if (yielded != stats.udp_datagrams) std::abort();
    if (stats.records != yielded + stats.malformed + stats.port_filtered) std::abort();
    if (status != CaptureStatus::kEnd && reader.error().empty()) std::abort();
  } catch (const CaptureError&) {
  }
  return 0;
}
