#include "daemon/pcap/endpoint.hpp"

#include <arpa/inet.h>

#include <cstring>

namespace pandarcap {

std::string to_string(const Endpoint& endpoint) {
  if (endpoint.ipv6) {
    char text[INET6_ADDRSTRLEN] = {};
    ::inet_ntop(AF_INET6, endpoint.ip6.data(), text, sizeof text);
    return std::string("[") + text + "]:" + std::to_string(endpoint.port);
  }
  return std::to_string(endpoint.ip >> 24) + '.' + std::to_string((endpoint.ip >> 16) & 0xFF) +
         '.' + std::to_string((endpoint.ip >> 8) & 0xFF) + '.' +
         std::to_string(endpoint.ip & 0xFF) + ':' + std::to_string(endpoint.port);
}

sockaddr_in to_sockaddr(const Endpoint& endpoint) noexcept {
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_addr.s_addr = htonl(endpoint.ip);
  address.sin_port = htons(endpoint.port);
  return address;
}

sockaddr_in6 to_sockaddr6(const Endpoint& endpoint) noexcept {
  sockaddr_in6 address{};
  address.sin6_family = AF_INET6;
  std::memcpy(&address.sin6_addr, endpoint.ip6.data(), endpoint.ip6.size());
  address.sin6_port = htons(endpoint.port);
  return address;
}

Endpoint to_endpoint(const sockaddr_in& address) noexcept {
  return Endpoint{ntohl(address.sin_addr.s_addr), ntohs(address.sin_port)};
}

Endpoint to_endpoint(const sockaddr_in6& address) noexcept {
  Endpoint endpoint{0, ntohs(address.sin6_port), true};
  std::memcpy(endpoint.ip6.data(), &address.sin6_addr, endpoint.ip6.size());
  return endpoint;
}

}  // namespace pandarcap
