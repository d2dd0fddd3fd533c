#include "daemon/live/live_port_probe.hpp"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>

namespace pandarcap::live {
namespace {

// Binds a fresh TCP socket of `family` to `address` (with SO_REUSEADDR, as the server's own
// socket is made) and closes it: 0 or the errno.
int try_bind(int family, const sockaddr* address, socklen_t length, bool v6only) noexcept {
  const int fd = ::socket(family, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return errno;
  const int one = 1;
  ::setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
  if (v6only) ::setsockopt(fd, IPPROTO_IPV6, IPV6_V6ONLY, &one, sizeof one);
  const int result = ::bind(fd, address, length) == 0 ? 0 : errno;
  ::close(fd);
  return result;
}

}  // namespace

int probe_ipv4_port(const std::string& ipv4_address, std::uint16_t port) noexcept {
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_port = htons(port);
  if (::inet_pton(AF_INET, ipv4_address.c_str(), &address.sin_addr) != 1) return EINVAL;
  return try_bind(AF_INET, reinterpret_cast<const sockaddr*>(&address), sizeof address, false);
}

bool ipv6_loopback_port_taken(std::uint16_t port) noexcept {
  sockaddr_in6 address{};
  address.sin6_family = AF_INET6;
  address.sin6_port = htons(port);
  address.sin6_addr = in6addr_loopback;
  return try_bind(AF_INET6, reinterpret_cast<const sockaddr*>(&address), sizeof address, true) ==
         EADDRINUSE;
}

}  // namespace pandarcap::live
