#include "core/wire_frame.hpp"

#include <algorithm>

namespace pandarcap {
namespace {

constexpr std::uint16_t kEthertypeIpv4 = 0x0800;
constexpr std::uint16_t kEthertypeVlan = 0x8100;  // 802.1Q
constexpr std::uint16_t kEthertypeQinQ = 0x88A8;  // 802.1ad
constexpr std::size_t kUdpBytes = 8;

std::uint16_t be16(const std::uint8_t* p) noexcept {
  return static_cast<std::uint16_t>(p[0] << 8 | p[1]);
}

std::uint32_t be32(const std::uint8_t* p) noexcept {
  return std::uint32_t{p[0]} << 24 | std::uint32_t{p[1]} << 16 | std::uint32_t{p[2]} << 8 | p[3];
}

}  // namespace

std::optional<WireFrame> parse_wire_frame(std::span<const std::uint8_t> frame,
                                          std::size_t wire_length) noexcept {
  const std::size_t held = frame.size();
  std::size_t offset = 12;
  if (held < offset + 2) return std::nullopt;
  std::uint16_t ethertype = be16(frame.data() + offset);
  // Tags still in the frame (the kernel takes the outer one out): at most two.
  for (int tags = 0; (ethertype == kEthertypeVlan || ethertype == kEthertypeQinQ) && tags < 2;
       ++tags) {
    offset += 4;
    if (held < offset + 2) return std::nullopt;
    ethertype = be16(frame.data() + offset);
  }
  offset += 2;
  if (ethertype != kEthertypeIpv4 || held < offset + 20) return std::nullopt;
  const std::uint8_t* ip = frame.data() + offset;
  const std::size_t ihl = std::size_t{ip[0] & 0x0Fu} * 4;
  if ((ip[0] >> 4) != 4 || ihl < 20 || ip[9] != 17 || held < offset + ihl + kUdpBytes) {
    return std::nullopt;
  }
  const std::uint16_t fragment = be16(ip + 6);
  if ((fragment & 0x1FFF) != 0) return std::nullopt;  // a later fragment: no UDP header

  WireFrame f;
  const std::uint8_t* udp = ip + ihl;
  f.header_bytes = offset + ihl + kUdpBytes;
  const std::uint16_t udp_length = be16(udp + 4);
  const std::size_t ip_length = be16(ip + 2);
  f.claimed_bytes =
      udp_length >= kUdpBytes ? udp_length - static_cast<std::uint32_t>(kUdpBytes) : 0;
  // The bytes after the UDP header, held here and on the wire.
  const std::size_t after_held = held - f.header_bytes;
  const std::size_t after_wire =
      wire_length > f.header_bytes ? wire_length - f.header_bytes : std::size_t{0};
  f.payload_bytes = std::min<std::size_t>(f.claimed_bytes, after_held);
  f.trailer_bytes = after_held - f.payload_bytes;
  f.arrived_bytes = static_cast<std::uint32_t>(std::min<std::size_t>(f.claimed_bytes, after_wire));
  const bool more_fragments = (fragment & 0x2000) != 0;
  const bool lengths_contradict = udp_length < kUdpBytes || ip_length < ihl + udp_length ||
                                  offset + ip_length > std::max(wire_length, held);
  f.truncated = more_fragments || lengths_contradict || f.payload_bytes < f.claimed_bytes;
  f.source_ip = be32(ip + 12);
  f.destination_ip = be32(ip + 16);
  f.source_port = be16(udp);
  f.destination_port = be16(udp + 2);
  return f;
}

}  // namespace pandarcap
