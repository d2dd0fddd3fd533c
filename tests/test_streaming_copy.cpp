// daemon/streaming_copy.hpp: the decode thread's copy of each datagram into a raw batch, past its
// cache. Whatever the length, the bytes asked for arrive whole and nothing past the rounded-up
// granule is touched; the source is read for exactly its bytes (a datagram in the packet ring's
// mapping may end where the mapping does); and a recorded packet keeps every field through
// record_raw's header copy.
#include <sys/mman.h>
#include <unistd.h>

#include <array>
#include <catch2/catch.hpp>
#include <cstdint>
#include <cstring>

#include "daemon/pipeline_types.hpp"
#include "daemon/streaming_copy.hpp"

namespace pandarcap {

TEST_CASE("streaming_copy copies every length whole and stays inside its granules",
          "[streaming_copy]") {
  alignas(64) std::array<std::uint8_t, 1280> src{};
  for (std::size_t i = 0; i < src.size(); ++i)
    src[i] = static_cast<std::uint8_t>(i * 7 + 3);
  for (std::size_t bytes = 0; bytes <= src.size(); ++bytes) {
    CAPTURE(bytes);
    // 64 guard bytes past the capacity: never written.
    alignas(64) std::array<std::uint8_t, 1280 + 64> dst;
    dst.fill(0xEE);
    streaming_copy(dst.data(), src.data(), bytes);
    streaming_stores_done();
    CHECK(std::memcmp(dst.data(), src.data(), bytes) == 0);
    const std::size_t rounded =
        (bytes + kStreamingGranule - 1) / kStreamingGranule * kStreamingGranule;
    bool untouched = true;
    for (std::size_t i = rounded; i < dst.size(); ++i)
      untouched = untouched && dst[i] == 0xEE;
    CHECK(untouched);
  }
}

TEST_CASE("streaming_copy reads no byte past its source: one that ends where a mapping does",
          "[streaming_copy]") {
  // Two pages, the second made unreadable: a source that ends at the first one's end is a
  // datagram at the end of the packet ring's last block. A read past it would fault.
  const std::size_t page = static_cast<std::size_t>(::sysconf(_SC_PAGESIZE));
  void* map = ::mmap(nullptr, 2 * page, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  REQUIRE(map != MAP_FAILED);
  auto* bytes = static_cast<std::uint8_t*>(map);
  for (std::size_t i = 0; i < page; ++i)
    bytes[i] = static_cast<std::uint8_t>(i * 13 + 5);
  REQUIRE(::mprotect(bytes + page, page, PROT_NONE) == 0);
  for (std::size_t length : {1u, 2u, 15u, 16u, 17u, 31u, 42u, 63u, 64u, 65u, 1262u, 1266u, 1280u}) {
    CAPTURE(length);
    const std::uint8_t* src = bytes + page - length;  // every alignment of the source's end
    alignas(64) std::array<std::uint8_t, 1280 + 64> dst;
    dst.fill(0xEE);
    streaming_copy(dst.data(), src, length);
    streaming_stores_done();
    CHECK(std::memcmp(dst.data(), src, length) == 0);
  }
  ::munmap(map, 2 * page);
}

TEST_CASE("a raw packet's header streams whole: every field as it was built", "[streaming_copy]") {
  RawPacketHeader header;
  header.receive_time_ns = 1'700'000'000'123'456'789;
  header.source.v4.sin_family = AF_INET;
  header.source.v4.sin_port = 0x1234;
  header.destination.v4.sin_family = AF_INET;
  header.length = 1266;
  header.original_length = 1300;
  header.wire_header_length = 46;
  for (std::uint8_t i = 0; i < 46; ++i)
    header.wire_header[i] = static_cast<std::uint8_t>(i + 1);
  header.wire_trailer_length = 6;
  header.wire_length = 1318;
  static RawPacket packet;  // as in a batch: line-aligned
  streaming_copy(static_cast<RawPacketHeader*>(&packet), &header, sizeof header);
  streaming_stores_done();
  CHECK(packet.receive_time_ns == header.receive_time_ns);
  CHECK(packet.source.v4.sin_port == 0x1234);
  CHECK(packet.length == 1266);
  CHECK(packet.original_length == 1300);
  CHECK(packet.wire_header_length == 46);
  CHECK(std::memcmp(packet.wire_header, header.wire_header, 46) == 0);
  CHECK(packet.wire_trailer_length == 6);
  CHECK(packet.wire_length == 1318);
  CHECK(reinterpret_cast<std::uintptr_t>(packet.payload) % 64 == 0);
}

}  // namespace pandarcap
