// Capture files built byte by byte, for tests that need a file no writer of ours makes: pcapng
// (the daemon records classic pcap only), and headers written wrong on purpose.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace pandarcap::test {

using Bytes = std::vector<std::uint8_t>;

inline void put_be16(Bytes& out, std::uint16_t v) {
  out.push_back(static_cast<std::uint8_t>(v >> 8));
  out.push_back(static_cast<std::uint8_t>(v));
}
inline void put_be32(Bytes& out, std::uint32_t v) {
  put_be16(out, static_cast<std::uint16_t>(v >> 16));
  put_be16(out, static_cast<std::uint16_t>(v));
}
inline void put_le16(Bytes& out, std::uint16_t v) {
  out.push_back(static_cast<std::uint8_t>(v));
  out.push_back(static_cast<std::uint8_t>(v >> 8));
}
inline void put_le32(Bytes& out, std::uint32_t v) {
  put_le16(out, static_cast<std::uint16_t>(v));
  put_le16(out, static_cast<std::uint16_t>(v >> 16));
}
inline std::uint16_t get_be16(const Bytes& in, std::size_t offset) {
  return static_cast<std::uint16_t>((in[offset] << 8) | in[offset + 1]);
}
inline void append(Bytes& out, const Bytes& tail) {
  out.insert(out.end(), tail.begin(), tail.end());
}

// pcapng (little-endian): one section, one Ethernet interface with nanosecond timestamps
// (if_tsresol = 9). A file is pcapng_header() followed by pcapng_packet()s.
inline Bytes pcapng_block(std::uint32_t type, Bytes body) {
  body.resize((body.size() + 3) / 4 * 4, 0);
  const auto total = static_cast<std::uint32_t>(12 + body.size());
  Bytes out;
  put_le32(out, type);
  put_le32(out, total);
  append(out, body);
  put_le32(out, total);
  return out;
}

inline Bytes pcapng_header() {
  constexpr std::uint16_t kLinktypeEthernet = 1;
  Bytes shb;
  put_le32(shb, 0x1A2B3C4D);  // byte-order magic
  put_le16(shb, 1);
  put_le16(shb, 0);
  put_le32(shb, 0xFFFFFFFF);  // section length unknown (-1)
  put_le32(shb, 0xFFFFFFFF);
  Bytes idb;
  put_le16(idb, kLinktypeEthernet);
  put_le16(idb, 0);
  put_le32(idb, 0);           // snaplen: none
  put_le16(idb, 9);           // option if_tsresol
  put_le16(idb, 1);           //   length 1
  append(idb, {9, 0, 0, 0});  //   10^-9 s, padded to 4
  put_le32(idb, 0);           // opt_endofopt
  Bytes out = pcapng_block(0x0A0D0D0A, shb);
  append(out, pcapng_block(1, idb));
  return out;
}

// An Enhanced Packet Block holding `frame` (an Ethernet frame) at `timestamp_ns`.
inline Bytes pcapng_packet(const Bytes& frame, std::uint64_t timestamp_ns) {
  Bytes epb;
  put_le32(epb, 0);  // interface 0
  put_le32(epb, static_cast<std::uint32_t>(timestamp_ns >> 32));
  put_le32(epb, static_cast<std::uint32_t>(timestamp_ns));
  put_le32(epb, static_cast<std::uint32_t>(frame.size()));
  put_le32(epb, static_cast<std::uint32_t>(frame.size()));
  append(epb, frame);
  return pcapng_block(6, epb);
}

}  // namespace pandarcap::test
