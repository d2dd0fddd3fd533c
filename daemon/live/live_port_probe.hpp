// Whether the live view's port can be bound, asked without keeping it: `pandarcapd
// --check-config` reports a port another program holds (foxglove_bridge listens on 8765 too), and
// the daemon warns when the IPv4 port it bound is held over IPv6 by another program (a viewer
// that opens ws://localhost:PORT may reach that one, over ::1). Plain C++17 sockets.
#pragma once

#include <cstdint>
#include <string>

namespace pandarcap::live {

// 0 when a TCP socket can bind `ipv4_address`:`port` now (and is closed again), else the errno
// of the failure (EADDRINUSE: in use; EADDRNOTAVAIL: not an address of this host; EACCES: a
// privileged port).
int probe_ipv4_port(const std::string& ipv4_address, std::uint16_t port) noexcept;

// Whether some socket holds TCP `port` on the IPv6 loopback (::1) or the IPv6 wildcard: a bind
// of [::1]:port with IPV6_V6ONLY fails with EADDRINUSE. False when IPv6 is off on this host.
bool ipv6_loopback_port_taken(std::uint16_t port) noexcept;

}  // namespace pandarcap::live
