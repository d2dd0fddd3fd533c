// Traffic made by hand for the tests: Ethernet frames for the veth tests, sent from the far
// end's packet socket (what a kernel's UDP socket would not send: a VLAN tag, IPv4 options, a
// trailer the IP length leaves out, a second tag), and UDP sockets that send as a given host.
#pragma once

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>

#include <catch2/catch.hpp>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "daemon/io/unique_fd.hpp"
#include "support/veth_pair.hpp"

namespace pandarcap::test {

// `ip`:`port` as a socket address.
inline sockaddr_in ipv4_endpoint(const std::string& ip, std::uint16_t port) {
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_port = htons(port);
  inet_pton(AF_INET, ip.c_str(), &address.sin_addr);
  return address;
}

// A UDP socket bound to `from_ip` (any port): what it sends comes from that host.
inline io::UniqueFd udp_socket_from(const std::string& from_ip) {
  io::UniqueFd fd(::socket(AF_INET, SOCK_DGRAM, 0));
  REQUIRE(fd);
  const sockaddr_in local = ipv4_endpoint(from_ip, 0);
  REQUIRE(::bind(fd.get(), reinterpret_cast<const sockaddr*>(&local), sizeof local) == 0);
  return fd;
}

// The Internet checksum (RFC 1071) of `n` bytes.
inline std::uint16_t ip_checksum(const std::uint8_t* p, std::size_t n) {
  std::uint32_t sum = 0;
  for (std::size_t i = 0; i + 1 < n; i += 2)
    sum += static_cast<std::uint32_t>(p[i] << 8 | p[i + 1]);
  if (n % 2) sum += static_cast<std::uint32_t>(p[n - 1] << 8);
  while (sum >> 16)
    sum = (sum & 0xFFFF) + (sum >> 16);
  return static_cast<std::uint16_t>(~sum);
}

inline std::vector<std::uint8_t> parse_mac(const std::string& text) {
  std::vector<std::uint8_t> mac;
  for (std::size_t i = 0; i + 1 < text.size(); i += 3)
    mac.push_back(static_cast<std::uint8_t>(std::stoul(text.substr(i, 2), nullptr, 16)));
  return mac;
}

// A frame from the far end to the near end's `port` (from 2368): Ethernet with a VLAN tag when
// `tci` is not 0 (and a second, inner one when `inner_tci` is not 0), IPv4 with `options` bytes
// of NOPs, UDP carrying `payload`, then `trailer` bytes the IP length leaves out.
inline std::vector<std::uint8_t> hand_frame(const VethPair& veth, std::uint16_t port,
                                            std::uint16_t tci,
                                            const std::vector<std::uint8_t>& payload,
                                            std::uint16_t ip_id, std::size_t trailer = 0,
                                            std::size_t options = 0, std::uint16_t inner_tci = 0) {
  std::vector<std::uint8_t> f = parse_mac(veth.near_mac());
  const std::vector<std::uint8_t> source = parse_mac(veth.far_mac());
  f.insert(f.end(), source.begin(), source.end());
  const auto be16 = [&](std::uint16_t v) {
    f.push_back(static_cast<std::uint8_t>(v >> 8));
    f.push_back(static_cast<std::uint8_t>(v));
  };
  for (const std::uint16_t tag : {tci, inner_tci}) {
    if (tag == 0) continue;
    be16(0x8100);
    be16(tag);
  }
  be16(0x0800);
  const std::size_t ip = f.size();
  const auto udp_length = static_cast<std::uint16_t>(8 + payload.size());
  be16(static_cast<std::uint16_t>(0x4500 + (options / 4 << 8)));
  be16(static_cast<std::uint16_t>(20 + options + udp_length));
  be16(ip_id);
  be16(0x4000);
  be16(0x4011);
  be16(0);
  for (const std::string& address : {veth.far_ip(), veth.near_ip()}) {
    in_addr a{};
    inet_pton(AF_INET, address.c_str(), &a);
    const auto* bytes = reinterpret_cast<const std::uint8_t*>(&a);
    f.insert(f.end(), bytes, bytes + 4);
  }
  f.insert(f.end(), options, std::uint8_t{1});  // NOPs
  const std::uint16_t sum = ip_checksum(f.data() + ip, 20 + options);
  f[ip + 10] = static_cast<std::uint8_t>(sum >> 8);
  f[ip + 11] = static_cast<std::uint8_t>(sum);
  be16(2368);
  be16(port);
  be16(udp_length);
  be16(0);
  f.insert(f.end(), payload.begin(), payload.end());
  for (std::size_t i = 0; i < trailer; ++i)
    f.push_back(static_cast<std::uint8_t>(0xA0 + i * 5));
  return f;
}

}  // namespace pandarcap::test
