// The IPv4 destinations this host's kernel delivers to itself, followed as they change: what the
// packet ring needs to take only what a UDP socket bound to 0.0.0.0 would be given. Such a socket
// is given a datagram only when the kernel's "local" routing table says its destination is this
// host's: an address of any interface, a subnet's broadcast, 127.0.0.0/8, a range routed as
// local (AnyIP). A frame that reaches the interface with this host's MAC and another destination
// (traffic routed through the host) is not for it.
//
// Two NETLINK_ROUTE sockets: one subscribed to the IPv4 route changes, one that asks for the
// whole table. Nothing here allocates after the start, and nothing waits but the start's first
// reading. A caller that finds a destination missing calls read_changes(), which applies the
// changes already queued (the kernel queues a new address's local route before any datagram to
// it can arrive, so it is taken from its first datagram). refresh(), once a second, reads the
// whole table again: the changes alone cannot be trusted (the kernel removes an interface's
// broadcast route, when it goes down or away, without a message; a queue that overflowed lost
// some), so whatever they leave wrong lasts a second at most.
#pragma once

#include <array>
#include <cstdint>

#include "daemon/io/unique_fd.hpp"

namespace pandarcap {

class LocalDestinations {
 public:
  static constexpr std::size_t kMaxRoutes = 512;

  // Subscribes and reads the table. Throws std::system_error naming the step.
  LocalDestinations();

  // Whether the kernel delivers `destination` (host order) to this host, as last read; true for
  // every destination while the local table has more than kMaxRoutes routes (it cannot be held:
  // nothing is refused then).
  bool contains(std::uint32_t destination) const noexcept;
  // Applies the changes queued since the last call, without waiting. A queue that overflowed
  // reads the whole table instead.
  void read_changes() noexcept;
  // Reads the whole table again, without waiting for more than the kernel's answer (a table that
  // does not come whole keeps the last one, with the changes applied).
  void refresh() noexcept {
    if (!load(/*patient=*/false)) read_changes();
  }
  std::size_t size() const noexcept { return current_.count; }
  bool overflowed() const noexcept { return overflow_; }

 private:
  // A route of the local table: a prefix delivered here (an address is a /32).
  struct Route {
    std::uint32_t network = 0;  // host order, masked
    std::uint8_t prefix = 0;
    std::uint8_t type = 0;  // RTN_LOCAL or RTN_BROADCAST
    std::uint32_t interface = 0;
    bool operator==(const Route&) const = default;
  };
  struct Table {
    std::array<Route, kMaxRoutes> routes{};
    std::size_t count = 0;
    bool overflow = false;  // more than kMaxRoutes
    void add(const Route& route) noexcept;
    void remove(const Route& route) noexcept;
  };
  // The whole table into loading_, then in place of the current one. `patient`: the start,
  // which may wait (two seconds at most) for the answer.
  bool load(bool patient) noexcept;
  // The local-table route a message names (RTM_NEWROUTE/RTM_DELROUTE), if it is one.
  static bool parse(const void* message, Route& route) noexcept;
  void set_overflow(bool overflow) noexcept;

  io::UniqueFd changes_;   // subscribed to RTMGRP_IPV4_ROUTE
  io::UniqueFd table_;     // asks for the whole table
  Table current_;          // what contains() answers from
  bool overflow_ = false;  // contains() says yes to every destination (logged when it changes)
  Table loading_;
  std::uint32_t sequence_ = 0;
  alignas(4) std::array<std::uint8_t, 32768> buffer_{};
};

}  // namespace pandarcap
