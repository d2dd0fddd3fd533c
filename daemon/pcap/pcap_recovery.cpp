#include "daemon/pcap/pcap_recovery.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstring>
#include <system_error>

#include "daemon/io/errors.hpp"
#include "daemon/io/file_output.hpp"
#include "daemon/io/unique_fd.hpp"
#include "daemon/pcap/pcap_writer.hpp"

namespace pandarcap {
namespace {

// Reads exactly `n` bytes at `offset`; false at (or past) the end of the file.
bool read_at(int fd, std::uint64_t offset, void* out, std::size_t n, const std::string& path) {
  std::size_t done = 0;
  while (done < n) {
    const ssize_t got =
        ::pread(fd, static_cast<char*>(out) + done, n - done, static_cast<off_t>(offset + done));
    if (got < 0) {
      if (errno == EINTR) continue;
      io::throw_errno("cannot read", path);
    }
    if (got == 0) return false;
    done += static_cast<std::size_t>(got);
  }
  return true;
}

std::uint32_t u32_at(const std::uint8_t* bytes) {
  std::uint32_t v = 0;
  std::memcpy(&v, bytes, sizeof v);  // native order, as written
  return v;
}

}  // namespace

std::optional<std::uint32_t> pcap_record_captured_bytes(
    const std::uint8_t* record_header) noexcept {
  const std::uint32_t captured = u32_at(record_header + 8);
  const std::uint32_t original = u32_at(record_header + 12);
  // Every record PcapWriter writes holds at least the headers it synthesises (Ethernet, IP, UDP):
  // a shorter one is not ours, e.g. the zeros a power cut can leave past the last sync.
  constexpr std::uint32_t kLeastRecordBytes = kPcapRecordOverheadBytes - kPcapRecordHeaderBytes;
  if (captured < kLeastRecordBytes || captured > kPcapSnaplen || captured > original) {
    return std::nullopt;
  }
  return captured;
}

PcapRecovery finish_interrupted_pcap(const std::string& path) {
  const auto [file, size] = open_leftover(path, O_RDWR);
  const int fd = file.get();

  // Ours: the file begins with PcapWriter's global header, or, shorter than it (killed between
  // creating the file and writing the header; empty included), with the start of it.
  PcapRecovery result;
  std::array<std::uint8_t, kPcapGlobalHeaderBytes> header{};
  const auto present = static_cast<std::size_t>(std::min<std::uint64_t>(size, header.size()));
  if (present > 0 && !read_at(fd, 0, header.data(), present, path)) return result;
  result.ours = std::memcmp(header.data(), pcap_global_header().data(), present) == 0;
  if (!result.ours || size < kPcapGlobalHeaderBytes) {
    result.kept_bytes = size;  // not a recording of ours (left alone), or one with no record
    return result;
  }
  std::uint64_t end = kPcapGlobalHeaderBytes;  // end of the last whole record
  std::array<std::uint8_t, kPcapRecordHeaderBytes> record{};
  while (read_at(fd, end, record.data(), record.size(), path)) {
    const std::optional<std::uint32_t> captured = pcap_record_captured_bytes(record.data());
    if (!captured) break;  // not a header of ours: the good part ends here
    const std::uint64_t next = end + kPcapRecordHeaderBytes + *captured;
    if (next > size) break;  // the record's bytes never all reached the file
    end = next;
    ++result.records;
  }
  if (end < size) {
    if (::ftruncate(fd, static_cast<off_t>(end)) != 0) io::throw_errno("cannot truncate", path);
  }
  result.kept_bytes = end;
  result.cut_bytes = size - end;
  return result;
}

}  // namespace pandarcap
