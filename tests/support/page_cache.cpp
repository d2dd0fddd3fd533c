#include "support/page_cache.hpp"

#include <fcntl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <catch2/catch.hpp>
#include <fstream>
#include <string>

namespace pandarcap::test {

namespace fs = std::filesystem;

std::vector<bool> cached_pages(const fs::path& file) {
  const int fd = ::open(file.c_str(), O_RDONLY | O_CLOEXEC);
  REQUIRE(fd >= 0);
  const std::size_t size = fs::file_size(file);
  const auto page = static_cast<std::size_t>(::sysconf(_SC_PAGESIZE));
  std::vector<unsigned char> in_core((size + page - 1) / page);
  if (size == 0) {
    ::close(fd);
    return {};
  }
  void* map = ::mmap(nullptr, size, PROT_READ, MAP_SHARED, fd, 0);
  ::close(fd);
  REQUIRE(map != MAP_FAILED);
  const int ok = ::mincore(map, size, in_core.data());
  ::munmap(map, size);
  REQUIRE(ok == 0);
  std::vector<bool> cached;
  for (const unsigned char flag : in_core)
    cached.push_back((flag & 1u) != 0);
  return cached;
}

void drop_from_page_cache(const fs::path& file) {
  const int fd = ::open(file.c_str(), O_RDONLY | O_CLOEXEC);
  REQUIRE(fd >= 0);
  REQUIRE(::fdatasync(fd) == 0);
  REQUIRE(::posix_fadvise(fd, 0, 0, POSIX_FADV_DONTNEED) == 0);
  ::close(fd);
}

bool drops_clean_pages(const fs::path& dir) {
  const fs::path probe = dir / ".page-cache-probe";
  const auto page = static_cast<std::size_t>(::sysconf(_SC_PAGESIZE));
  {
    const std::string bytes(16 * page, 'p');
    std::ofstream(probe, std::ios::binary) << bytes;
  }
  drop_from_page_cache(probe);
  const std::vector<bool> cached = cached_pages(probe);
  fs::remove(probe);
  return std::count(cached.begin(), cached.end(), true) == 0;
}

std::uint64_t storage_bytes_read() {
  std::ifstream io("/proc/self/io");
  std::string key;
  std::uint64_t value = 0;
  while (io >> key >> value) {
    if (key == "read_bytes:") return value;
  }
  FAIL("no read_bytes in /proc/self/io");
  return 0;
}

}  // namespace pandarcap::test
