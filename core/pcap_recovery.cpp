#include "pcap_recovery.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <cstring>
#include <system_error>

namespace pandarcap {
namespace {

constexpr std::uint32_t kMagicMicroseconds = 0xA1B2C3D4;
constexpr std::uint32_t kSnaplen = 262144;  // PcapWriter's; no record of ours is longer
constexpr std::uint32_t kLinktypeEthernet = 1;
constexpr std::size_t kGlobalHeaderBytes = 24;
constexpr std::size_t kRecordHeaderBytes = 16;

[[noreturn]] void fail(const char* what, const std::string& path) {
  throw std::system_error(errno, std::generic_category(), std::string(what) + " '" + path + "'");
}

// Reads exactly `n` bytes at `offset`; false at (or past) the end of the file.
bool read_at(int fd, std::uint64_t offset, void* out, std::size_t n, const std::string& path) {
  std::size_t done = 0;
  while (done < n) {
    const ssize_t got =
        ::pread(fd, static_cast<char*>(out) + done, n - done, static_cast<off_t>(offset + done));
    if (got < 0) {
      if (errno == EINTR) continue;
      fail("cannot read", path);
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

PcapRecovery finish_interrupted_pcap(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDWR | O_CLOEXEC);
  if (fd < 0) fail("cannot open", path);
  struct Closer {
    int fd;
    ~Closer() { ::close(fd); }
  } closer{fd};
  struct stat info {};
  if (::fstat(fd, &info) != 0) fail("cannot stat", path);
  const auto size = static_cast<std::uint64_t>(info.st_size);

  PcapRecovery result;
  std::array<std::uint8_t, kGlobalHeaderBytes> header{};
  if (size < kGlobalHeaderBytes) {
    // Killed between creating the file and writing its header: ours if what is there is the
    // start of the header PcapWriter writes (an empty file included). No record either way.
    if (size > 0 && !read_at(fd, 0, header.data(), static_cast<std::size_t>(size), path)) {
      return result;
    }
    std::array<std::uint8_t, kGlobalHeaderBytes> expected{};  // as PcapWriter lays it out
    const auto put = [&](std::size_t at, auto value) {
      std::memcpy(&expected[at], &value, sizeof value);
    };
    put(0, kMagicMicroseconds);
    put(4, std::uint16_t{2});  // version 2.4
    put(6, std::uint16_t{4});
    put(16, kSnaplen);
    put(20, kLinktypeEthernet);
    result.ours = std::memcmp(header.data(), expected.data(), static_cast<std::size_t>(size)) == 0;
    result.kept_bytes = size;
    return result;
  }
  if (read_at(fd, 0, header.data(), header.size(), path)) {
    result.ours =
        u32_at(header.data()) == kMagicMicroseconds && u32_at(header.data() + 16) == kSnaplen;
  }
  if (!result.ours) {
    result.kept_bytes = size;  // not a recording of ours: left alone
    return result;
  }
  std::uint64_t end = kGlobalHeaderBytes;  // end of the last whole record
  std::array<std::uint8_t, kRecordHeaderBytes> record{};
  while (read_at(fd, end, record.data(), record.size(), path)) {
    const std::uint32_t captured = u32_at(record.data() + 8);
    const std::uint32_t original = u32_at(record.data() + 12);
    // A header that cannot be one of ours is where the good part ends.
    if (captured > kSnaplen || captured != original) break;
    const std::uint64_t next = end + kRecordHeaderBytes + captured;
    if (next > size) break;  // the record's bytes never all reached the file
    end = next;
    ++result.records;
  }
  if (end < size) {
    if (::ftruncate(fd, static_cast<off_t>(end)) != 0) fail("cannot truncate", path);
  }
  result.kept_bytes = end;
  result.cut_bytes = size - end;
  return result;
}

}  // namespace pandarcap
