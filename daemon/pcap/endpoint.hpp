// Endpoint: an IP address and UDP port as a capture file or a socket holds them, IPv4 or IPv6.
//
// The sensor speaks IPv4 and the daemon binds an IPv4 socket; IPv6 endpoints come from replayed
// captures (a recording made on an IPv6 network, or converted by a tool that writes IPv6), and
// the recording writes them back as they came.
#pragma once

#include <netinet/in.h>

#include <array>
#include <cstdint>
#include <string>

namespace pandarcap {

struct Endpoint {
  std::uint32_t ip = 0;  // IPv4 address in host byte order (192.168.1.201 = 0xC0A801C9); 0 for IPv6
  std::uint16_t port = 0;                 // host byte order
  bool ipv6 = false;                      // the address is `ip6`, not `ip`
  std::array<std::uint8_t, 16> ip6 = {};  // IPv6 address bytes, as on the wire
  friend bool operator==(const Endpoint&, const Endpoint&) = default;
};

// "192.168.1.201:2368", "[fd00::201]:2368"
std::string to_string(const Endpoint& endpoint);

// The same endpoint as the socket API holds it (network byte order), and back.
sockaddr_in to_sockaddr(const Endpoint& endpoint) noexcept;    // an IPv4 endpoint
sockaddr_in6 to_sockaddr6(const Endpoint& endpoint) noexcept;  // an IPv6 endpoint
Endpoint to_endpoint(const sockaddr_in& address) noexcept;
Endpoint to_endpoint(const sockaddr_in6& address) noexcept;

}  // namespace pandarcap
