// The IPv4 destinations this host's kernel delivers to itself, followed as they change: what the
// packet ring needs to take only what a UDP socket bound to 0.0.0.0 would be given. Such a socket
// is given a datagram only when the kernel's "local" routing table says its destination is this
// host's: an address of any interface, a subnet's broadcast, 127.0.0.0/8, a range routed as
// local (AnyIP). A frame that reaches the interface with this host's MAC and another destination
// (traffic routed through the host) is not for it.
//
// A NETLINK_ROUTE socket subscribed to the IPv4 route changes, the table dumped once at start.
// Nothing here waits or allocates after the start: contains() answers from a fixed table, and a
// caller that finds a destination missing calls refresh(), which reads the changes already queued
// (the kernel queues a new address's local route before any datagram to it can arrive, so it is
// found when its first datagram is). refresh() once a second as well takes removed ones out.
#pragma once

#include <array>
#include <cstdint>

#include "daemon/io/unique_fd.hpp"

namespace pandarcap {

class LocalDestinations {
 public:
  static constexpr std::size_t kMaxRoutes = 512;

  // Subscribes and reads the local table. Throws std::system_error naming the step.
  LocalDestinations();

  // Whether the kernel delivers `destination` (host order) to this host, as last read; true for
  // every destination when the local table has more than kMaxRoutes routes (it could not be held:
  // nothing is refused then).
  bool contains(std::uint32_t destination) const noexcept;
  // Reads the changes queued since the last call (without waiting). After an overflow of the
  // socket's queue (changes lost), reads the whole table again.
  void refresh() noexcept;
  std::size_t size() const noexcept { return count_; }

 private:
  // A route of the local table: a prefix delivered here (an address is a /32).
  struct Route {
    std::uint32_t network = 0;  // host order, masked
    std::uint8_t prefix = 0;
    std::uint8_t type = 0;  // RTN_LOCAL or RTN_BROADCAST
    std::uint32_t interface = 0;
    bool operator==(const Route&) const = default;
  };
  // Asks for the whole table (an RTM_GETROUTE dump); its answers are read as changes are.
  bool request_dump() noexcept;
  // Reads what is queued; `wait_for_dump`: until the dump's end (start-up only, bounded).
  void read_messages(bool wait_for_dump) noexcept;
  void apply(const void* message) noexcept;
  void add(const Route& route) noexcept;
  void remove(const Route& route) noexcept;

  io::UniqueFd fd_;
  std::array<Route, kMaxRoutes> routes_{};
  std::size_t count_ = 0;
  bool overflow_ = false;  // more than kMaxRoutes: contains() says yes to every destination
  std::uint32_t dump_sequence_ = 0;
  alignas(4) std::array<std::uint8_t, 32768> buffer_{};
};

}  // namespace pandarcap
