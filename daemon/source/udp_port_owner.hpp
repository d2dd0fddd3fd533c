// Who holds a UDP port: for the hint when pandarcapd cannot bind its data port ("Address
// already in use"). The kernel lists every UDP socket in /proc/net/udp (local address, port and
// the socket's inode); a process's open sockets are the /proc/PID/fd links to "socket:[INODE]".
// Best effort: another user's processes cannot be looked into without privilege, and then only
// the fact that the port is held is known.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace pandarcap {

struct UdpSocketEntry {
  std::uint32_t address = 0;  // host order
  std::uint16_t port = 0;
  std::uint64_t inode = 0;
};

// The sockets in /proc/net/udp's text (its header line skipped; malformed lines ignored).
std::vector<UdpSocketEntry> parse_proc_net_udp(std::string_view text);

struct PortOwner {
  std::uint32_t address = 0;  // the holder's local address, host order
  std::optional<int> pid;     // found in /proc/PID/fd, where this user may look
  std::string command;        // /proc/PID/comm
};

// Who holds UDP `port` on this machine, reading /proc; nothing when no socket has it.
std::optional<PortOwner> udp_port_owner(std::uint16_t port);

// The hint for a bind that failed with EADDRINUSE: "UDP port 2368 is held by pid 1234
// (pandarcapd) on 0.0.0.0; ...". Empty when /proc says nothing.
std::string port_in_use_hint(std::uint16_t port);

}  // namespace pandarcap
