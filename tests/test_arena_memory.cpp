// daemon/arena_memory: the frame arenas' memory, aligned for O_DIRECT and offered for huge pages,
// and the arenas the pipeline lays out in it.
#include <sys/mman.h>
#include <sys/prctl.h>
#include <unistd.h>

#if defined(__SANITIZE_ADDRESS__)
#include <sanitizer/asan_interface.h>
#endif

#include <algorithm>
#include <catch2/catch.hpp>
#include <cerrno>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "config/daemon_config.hpp"
#include "daemon/arena_memory.hpp"
#include "daemon/daemon_options.hpp"
#include "daemon/io/file_output.hpp"
#include "daemon/pipeline.hpp"

using namespace pandarcap;

namespace {

// The "THPeligible" line of the mapping that holds `address` (/proc/self/smaps): 1 when the
// kernel may back it with huge pages. -1: the mapping or the line was not found.
int thp_eligible(const void* address) {
  const auto at = reinterpret_cast<std::uintptr_t>(address);
  std::ifstream smaps("/proc/self/smaps");
  std::string line;
  bool inside = false;
  while (std::getline(smaps, line)) {
    std::uintptr_t start = 0, end = 0;
    char dash = 0;
    std::istringstream range(line);
    if (range >> std::hex >> start >> dash >> end && dash == '-' &&
        line.find(':') > line.find(' ')) {
      inside = start <= at && at < end;
      continue;
    }
    if (inside && line.rfind("THPeligible:", 0) == 0) return std::stoi(line.substr(12));
  }
  return -1;
}

// What the kernel says of a mapping this process asks huge pages for itself (the control):
// THPeligible 1 where the system offers them (THP "always" or "madvise") and this process may
// have them; 0 under THP "never", PR_SET_THP_DISABLE, or QEMU's user-mode emulator (which drops
// madvise(MADV_HUGEPAGE): the arm64 workflow runs these tests under it).
int control_eligible() {
  const std::size_t bytes = 3 * ArenaMemory::kHugePage;
  void* const p =
      ::mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  REQUIRE(p != MAP_FAILED);
  (void)::madvise(p, bytes, MADV_HUGEPAGE);
  const int eligible = thp_eligible(static_cast<char*>(p) + ArenaMemory::kHugePage);
  ::munmap(p, bytes);
  return eligible;
}

}  // namespace

TEST_CASE("ArenaMemory: aligned to huge pages, zero-filled, and as long as asked", "[io]") {
  for (const std::size_t bytes :
       {std::size_t{1}, std::size_t{4096}, ArenaMemory::kHugePage - 1, ArenaMemory::kHugePage,
        ArenaMemory::kHugePage + 1, std::size_t{16'560'000}}) {
    CAPTURE(bytes);
    ArenaMemory memory(bytes);
    REQUIRE(memory.data() != nullptr);
    CHECK(reinterpret_cast<std::uintptr_t>(memory.data()) % ArenaMemory::kHugePage == 0);
    CHECK(memory.size() >= bytes);
    CHECK(memory.size() % ArenaMemory::kHugePage == 0);
    CHECK(memory.size() < bytes + ArenaMemory::kHugePage);
    std::size_t nonzero = 0;
    for (std::size_t i = 0; i < bytes; ++i)
      nonzero += memory.data()[i] != 0;
    CHECK(nonzero == 0);
    // Writable to its last byte (a mapping trimmed short would fault here).
    memory.data()[memory.size() - 1] = 0xAB;
    CHECK(memory.data()[memory.size() - 1] == 0xAB);
  }
}

TEST_CASE("ArenaMemory: every page asked for is resident at construction", "[io]") {
  // Populated at once (MADV_POPULATE_WRITE, or stores where the kernel lacks it): the decode
  // thread's first store into an arena takes no page fault. mincore says which pages are there.
  // Where the call succeeds without populating (QEMU's user-mode emulator takes madvise as a
  // hint and does nothing: the arm64 workflow runs these tests under it), nothing is expected;
  // the control says which.
  const std::size_t page = static_cast<std::size_t>(::sysconf(_SC_PAGESIZE));
  const auto resident_pages = [page](void* p, std::size_t bytes) {
    const std::size_t pages = (bytes + page - 1) / page;
    std::vector<unsigned char> resident(pages, 0);
    REQUIRE(::mincore(p, pages * page, resident.data()) == 0);
    return static_cast<std::size_t>(
        std::ranges::count_if(resident, [](unsigned char r) { return (r & 1) != 0; }));
  };
  void* const control =
      ::mmap(nullptr, page, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  REQUIRE(control != MAP_FAILED);
  const bool populates = ::madvise(control, page, MADV_POPULATE_WRITE) != 0 ||  // then stores
                         resident_pages(control, page) == 1;
  ::munmap(control, page);
  if (!populates) WARN("madvise(MADV_POPULATE_WRITE) populates nothing here (an emulator?)");
  for (const std::size_t bytes : {std::size_t{4096}, std::size_t{16'560'000}}) {
    CAPTURE(bytes);
    ArenaMemory memory(bytes);
    if (populates) CHECK(resident_pages(memory.data(), bytes) == (bytes + page - 1) / page);
  }
}

TEST_CASE("ArenaMemory: the kernel may back it with huge pages where it offers them", "[io]") {
  ArenaMemory memory(3 * ArenaMemory::kHugePage);
  const int eligible = thp_eligible(memory.data());
  REQUIRE(eligible != -1);  // the mapping is there, and the kernel says
  // As eligible as a mapping the test asks huge pages for itself: 1 on this machine ("madvise"),
  // and without its madvise the arena's would say 0 there.
  const int control = control_eligible();
  REQUIRE(control != -1);
  CHECK(eligible == control);
}

TEST_CASE("ArenaMemory: huge pages expected only where this process can get them", "[io]") {
  // A process refused huge pages whatever the system offers: PR_SET_THP_DISABLE (inherited from
  // whatever started the tests; QEMU's user-mode emulator refuses them the same way). The
  // expectation follows the process, not /sys/kernel/mm/transparent_hugepage/enabled.
  if (::prctl(PR_SET_THP_DISABLE, 1, 0, 0, 0) != 0) {
    // QEMU's user-mode emulator does not pass this prctl on (EINVAL): nothing to refuse with.
    WARN("prctl(PR_SET_THP_DISABLE) refused: " << std::strerror(errno));
    return;
  }
  int eligible = -1, control = -1;
  {
    ArenaMemory memory(3 * ArenaMemory::kHugePage);
    eligible = thp_eligible(memory.data());
    control = control_eligible();
  }
  ::prctl(PR_SET_THP_DISABLE, 0, 0, 0, 0);  // the tests after this one in the same process
  REQUIRE(eligible != -1);
  CHECK(control == 0);
  CHECK(eligible == control);
}

TEST_CASE("Pipeline: every arena in the one mapping, aligned for O_DIRECT, none overlapping",
          "[io]") {
  DaemonConfig config;
  for (const std::uint32_t count : {2u, 3u, 4u, 7u}) {
    for (const std::uint32_t points : {1000u, 1001u, 180'000u}) {
      CAPTURE(count, points);
      config.arenas.count = count;
      Pipeline pipeline(config, points, config.ring.slots);
      REQUIRE(pipeline.arenas.size() == count);
      const std::uint8_t* const begin = pipeline.arena_memory.data();
      const std::uint8_t* const end = begin + pipeline.arena_memory.size();
      std::set<const std::uint8_t*> starts;
      const std::uint8_t* previous_end = begin;
      for (const auto& arena : pipeline.arenas) {
        const std::span<std::uint8_t> bytes = arena->frame.encoded;
        CHECK(bytes.size() == points * pcd_point_bytes(pcd_format(config).layout));
        CHECK(reinterpret_cast<std::uintptr_t>(bytes.data()) % kDirectIoBlock == 0);
        // After the one before, a block that is no arena's between them.
        if (!starts.empty()) CHECK(bytes.data() >= previous_end + kDirectIoBlock);
        CHECK(bytes.data() + bytes.size() + kDirectIoBlock <= end);
#if defined(__SANITIZE_ADDRESS__)
        // ASan reports a write past an arena's end, as when each was an allocation of its own.
        CHECK(__asan_address_is_poisoned(bytes.data() + bytes.size()));
        CHECK(__asan_address_is_poisoned(bytes.data() + bytes.size() + kDirectIoBlock - 1));
        CHECK_FALSE(__asan_address_is_poisoned(bytes.data()));
        CHECK_FALSE(__asan_address_is_poisoned(&bytes.back()));
#endif
        previous_end = bytes.data() + bytes.size();
        starts.insert(bytes.data());
        // Each arena's last byte is its own: written through one, read back from the others.
        bytes.back() = static_cast<std::uint8_t>(starts.size());
      }
      CHECK(starts.size() == count);
      std::uint8_t n = 0;
      for (const auto& arena : pipeline.arenas)
        CHECK(arena->frame.encoded.back() == ++n);
    }
  }
}
