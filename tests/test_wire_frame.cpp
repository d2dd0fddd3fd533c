// core/wire_frame.hpp: the packet_ring receiver's reading of a frame, every length held against
// the bytes that are there. A matrix of frames a wire can carry, well-formed and not.
#include <catch2/catch.hpp>
#include <cstdint>
#include <vector>

#include "core/wire_frame.hpp"

namespace pandarcap {
namespace {

struct FrameSpec {
  int tags = 0;                     // in-band 802.1Q tags
  std::size_t options = 0;          // IPv4 option bytes (a multiple of 4)
  std::size_t payload = 100;        // UDP payload bytes in the frame
  int udp_length_delta = 0;         // the UDP length field minus the true one
  int ip_length_delta = 0;          // the IP total length minus the true one
  std::uint16_t fragment = 0x4000;  // DF
  std::size_t padding = 0;
  std::uint16_t ethertype = 0x0800;
  std::uint8_t protocol = 17;
};

std::vector<std::uint8_t> frame(const FrameSpec& s) {
  std::vector<std::uint8_t> f(12, 0xAA);
  const auto be16 = [&](std::uint32_t v) {
    f.push_back(static_cast<std::uint8_t>(v >> 8));
    f.push_back(static_cast<std::uint8_t>(v));
  };
  for (int t = 0; t < s.tags; ++t) {
    be16(0x8100);
    be16(7);
  }
  be16(s.ethertype);
  const std::size_t ihl = 20 + s.options;
  const std::size_t udp_length = 8 + s.payload;
  f.push_back(static_cast<std::uint8_t>(0x40 | ihl / 4));
  f.push_back(0);
  be16(static_cast<std::uint32_t>(static_cast<int>(ihl + udp_length) + s.ip_length_delta));
  be16(1);
  be16(s.fragment);
  f.push_back(64);
  f.push_back(s.protocol);
  be16(0);
  for (int b : {10, 0, 0, 2, 10, 0, 0, 1})
    f.push_back(static_cast<std::uint8_t>(b));
  f.insert(f.end(), s.options, 1);
  be16(10000);
  be16(2368);
  be16(static_cast<std::uint32_t>(static_cast<int>(udp_length) + s.udp_length_delta));
  be16(0);
  f.insert(f.end(), s.payload, 0x5A);
  f.insert(f.end(), s.padding, 0);
  return f;
}

}  // namespace

TEST_CASE("wire frame: tags, options, padding, lying lengths, fragments, other protocols",
          "[packet_ring][wire_frame]") {
  SECTION("well formed: every tag count and option length") {
    for (int tags : {0, 1, 2}) {
      for (std::size_t options : {0u, 4u, 40u}) {
        for (std::size_t payload : {0u, 1u, 1266u}) {
          const auto f = frame({tags, options, payload});
          const auto w = parse_wire_frame(f, f.size());
          INFO(tags << " tags, " << options << " option bytes, " << payload << " bytes");
          REQUIRE(w);
          CHECK(w->header_bytes == 14 + 4u * tags + 20 + options + 8);
          CHECK(w->payload_bytes == payload);
          CHECK(w->claimed_bytes == payload);
          CHECK(w->arrived_bytes == payload);
          CHECK(w->trailer_bytes == 0);
          CHECK_FALSE(w->truncated);
          CHECK(w->source_ip == 0x0A000002u);
          CHECK(w->destination_ip == 0x0A000001u);
          CHECK(w->source_port == 10000);
          CHECK(w->destination_port == 2368);
        }
      }
    }
  }
  SECTION("Ethernet padding is a trailer, not payload") {
    const auto f = frame({.payload = 4, .padding = 14});
    const auto w = parse_wire_frame(f, f.size());
    REQUIRE(w);
    CHECK(w->payload_bytes == 4);
    CHECK(w->trailer_bytes == 14);
    CHECK_FALSE(w->truncated);
  }
  SECTION("a UDP length past what is there: truncated, only what arrived counted") {
    const auto f = frame({.payload = 100, .udp_length_delta = 1900});
    const auto w = parse_wire_frame(f, f.size());
    REQUIRE(w);
    CHECK(w->claimed_bytes == 2000);
    CHECK(w->payload_bytes == 100);
    CHECK(w->arrived_bytes == 100);
    CHECK(w->truncated);
  }
  SECTION("a UDP length short of the IP packet: the datagram is what it says, the rest trailer") {
    const auto f = frame({.payload = 100, .udp_length_delta = -50});
    const auto w = parse_wire_frame(f, f.size());
    REQUIRE(w);
    CHECK(w->payload_bytes == 50);
    CHECK(w->trailer_bytes == 50);
    CHECK_FALSE(w->truncated);  // the kernel's UDP trims the same way
  }
  SECTION("contradictions: UDP length under 8, IP length past the frame or short of UDP's") {
    for (const FrameSpec& s :
         {FrameSpec{.udp_length_delta = -101}, FrameSpec{.ip_length_delta = 60},
          FrameSpec{.ip_length_delta = -20}}) {
      const auto f = frame(s);
      const auto w = parse_wire_frame(f, f.size());
      REQUIRE(w);
      CHECK(w->truncated);
    }
  }
  SECTION("held less than the wire had (a jumbo frame past the snap length)") {
    auto f = frame({.payload = 8000});
    const std::size_t wire = f.size();
    f.resize(2000);
    const auto w = parse_wire_frame(f, wire);
    REQUIRE(w);
    CHECK(w->claimed_bytes == 8000);
    CHECK(w->arrived_bytes == 8000);
    CHECK(w->payload_bytes == 2000 - 42);
    CHECK(w->truncated);
  }
  SECTION("a first fragment is truncated; a later one, IPv6, TCP, ARP are not datagrams here") {
    const auto first = frame({.fragment = 0x2000});
    REQUIRE(parse_wire_frame(first, first.size()));
    CHECK(parse_wire_frame(first, first.size())->truncated);
    for (const FrameSpec& s :
         {FrameSpec{.fragment = 0x00B9}, FrameSpec{.ethertype = 0x86DD},
          FrameSpec{.ethertype = 0x0806}, FrameSpec{.protocol = 6}, FrameSpec{.tags = 3}}) {
      const auto f = frame(s);
      CHECK_FALSE(parse_wire_frame(f, f.size()));
    }
  }
  SECTION("cut anywhere inside the headers: nothing, never a read past the end") {
    const auto whole = frame({.tags = 1, .options = 8});
    for (std::size_t n = 0; n < 14 + 4 + 28 + 8; ++n) {
      const std::vector<std::uint8_t> cut(whole.begin(), whole.begin() + static_cast<long>(n));
      CHECK_FALSE(parse_wire_frame(cut, whole.size()));
    }
  }
}

}  // namespace pandarcap
