#include "daemon/source/local_destinations.hpp"

#include <arpa/inet.h>
#include <linux/netlink.h>
#include <linux/rtnetlink.h>
#include <poll.h>
#include <spdlog/spdlog.h>
#include <sys/socket.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>

#include "daemon/io/errors.hpp"

namespace pandarcap {
namespace {

io::UniqueFd netlink_socket(std::uint32_t groups, const char* what) {
  io::UniqueFd fd(::socket(AF_NETLINK, SOCK_RAW | SOCK_NONBLOCK | SOCK_CLOEXEC, NETLINK_ROUTE));
  if (!fd) io::throw_errno(what);
  sockaddr_nl local{};
  local.nl_family = AF_NETLINK;
  local.nl_groups = groups;
  if (::bind(fd.get(), reinterpret_cast<const sockaddr*>(&local), sizeof local) != 0)
    io::throw_errno(what);
  return fd;
}

}  // namespace

LocalDestinations::LocalDestinations()
    : changes_(netlink_socket(RTMGRP_IPV4_ROUTE, "netlink socket (this host's route changes)")),
      table_(netlink_socket(0, "netlink socket (this host's local routes)")) {
  if (!load(/*patient=*/true)) io::throw_errno("netlink RTM_GETROUTE (this host's local routes)");
}

bool LocalDestinations::contains(std::uint32_t destination) const noexcept {
  if (overflow_) return true;
  const auto end = current_.routes.begin() + static_cast<std::ptrdiff_t>(current_.count);
  return std::any_of(current_.routes.begin(), end, [&](const Route& r) {
    return r.prefix == 0 || ((destination ^ r.network) >> (32 - r.prefix)) == 0;
  });
}

void LocalDestinations::Table::add(const Route& route) noexcept {
  const auto end = routes.begin() + static_cast<std::ptrdiff_t>(count);
  if (std::find(routes.begin(), end, route) != end) return;
  if (count == routes.size()) {
    overflow = true;
    return;
  }
  routes[count++] = route;
}

void LocalDestinations::Table::remove(const Route& route) noexcept {
  const auto end = routes.begin() + static_cast<std::ptrdiff_t>(count);
  const auto it = std::find(routes.begin(), end, route);
  if (it == end) return;
  *it = routes[--count];
}

void LocalDestinations::set_overflow(bool overflow) noexcept {
  if (overflow && !overflow_) {
    spdlog::warn(
        "packet ring: this host's local routing table has more than {} routes: a datagram to "
        "any address that reaches the interface with its MAC is taken until it has fewer",
        kMaxRoutes);
  } else if (!overflow && overflow_) {
    spdlog::info("packet ring: the local routing table has {} routes again: followed",
                 current_.count);
  }
  overflow_ = overflow;
}

void LocalDestinations::read_changes() noexcept {
  for (;;) {
    const ssize_t n = ::recv(changes_.get(), buffer_.data(), buffer_.size(), MSG_DONTWAIT);
    if (n < 0) {
      if (errno == EINTR) continue;
      if (errno == ENOBUFS) {
        // Changes were lost: the whole table, read now, says what they would have.
        load(/*patient=*/false);
      }
      return;
    }
    auto left = static_cast<unsigned>(n);
    for (auto* h = reinterpret_cast<const nlmsghdr*>(buffer_.data()); NLMSG_OK(h, left);
         h = NLMSG_NEXT(h, left)) {
      Route route;
      if (!parse(h, route)) continue;
      if (h->nlmsg_type == RTM_NEWROUTE) {
        current_.add(route);
        // A route past the table's room: every destination until a whole table that fits is read.
        if (current_.overflow) set_overflow(true);
      } else {
        current_.remove(route);
      }
    }
  }
}

bool LocalDestinations::load(bool patient) noexcept {
  // The changes queued so far are older than the table about to be read: dropped, not applied
  // after it (an address added and gone again would come back).
  while (::recv(changes_.get(), buffer_.data(), buffer_.size(), MSG_DONTWAIT) > 0 ||
         errno == ENOBUFS || errno == EINTR) {
  }
  struct {
    nlmsghdr header;
    rtmsg body;
  } request{};
  request.header.nlmsg_len = sizeof request;
  request.header.nlmsg_type = RTM_GETROUTE;
  request.header.nlmsg_flags = NLM_F_REQUEST | NLM_F_DUMP;
  request.header.nlmsg_seq = ++sequence_;
  request.body.rtm_family = AF_INET;
  request.body.rtm_table = RT_TABLE_LOCAL;
  sockaddr_nl kernel{};
  kernel.nl_family = AF_NETLINK;
  // An answer to an earlier request left unread (one that did not come whole) is not this one's.
  while (::recv(table_.get(), buffer_.data(), buffer_.size(), MSG_DONTWAIT) > 0) {
  }
  if (::sendto(table_.get(), &request, sizeof request, 0, reinterpret_cast<sockaddr*>(&kernel),
               sizeof kernel) != static_cast<ssize_t>(sizeof request)) {
    return false;
  }
  loading_.count = 0;
  loading_.overflow = false;
  // The kernel writes the answer as it is read: it is there at once. The start alone waits for
  // it (two seconds at most); a reload that finds it late keeps the table it has.
  const auto give_up = std::chrono::steady_clock::now() +
                       (patient ? std::chrono::milliseconds(2000) : std::chrono::milliseconds(0));
  for (;;) {
    const ssize_t n = ::recv(table_.get(), buffer_.data(), buffer_.size(), MSG_DONTWAIT);
    if (n < 0) {
      if (errno == EINTR) continue;
      if ((errno != EAGAIN && errno != EWOULDBLOCK) ||
          std::chrono::steady_clock::now() >= give_up) {
        return false;
      }
      pollfd pfd{table_.get(), POLLIN, 0};
      ::poll(&pfd, 1, 100);
      continue;
    }
    auto left = static_cast<unsigned>(n);
    for (auto* h = reinterpret_cast<const nlmsghdr*>(buffer_.data()); NLMSG_OK(h, left);
         h = NLMSG_NEXT(h, left)) {
      if (h->nlmsg_seq != sequence_) continue;
      if (h->nlmsg_type == NLMSG_ERROR) return false;
      if (h->nlmsg_type == NLMSG_DONE) {
        std::copy_n(loading_.routes.begin(), loading_.count, current_.routes.begin());
        current_.count = loading_.count;
        current_.overflow = loading_.overflow;
        set_overflow(loading_.overflow);
        return true;
      }
      Route route;
      if (h->nlmsg_type == RTM_NEWROUTE && parse(h, route)) loading_.add(route);
    }
  }
}

bool LocalDestinations::parse(const void* message, Route& route) noexcept {
  const auto* header = static_cast<const nlmsghdr*>(message);
  if (header->nlmsg_type != RTM_NEWROUTE && header->nlmsg_type != RTM_DELROUTE) return false;
  if (header->nlmsg_len < NLMSG_LENGTH(sizeof(rtmsg))) return false;
  const auto* body = static_cast<const rtmsg*>(NLMSG_DATA(header));
  if (body->rtm_family != AF_INET || body->rtm_dst_len > 32) return false;
  if (body->rtm_type != RTN_LOCAL && body->rtm_type != RTN_BROADCAST) return false;
  std::uint32_t table = body->rtm_table;
  route = Route{};
  route.prefix = body->rtm_dst_len;
  route.type = body->rtm_type;
  int left = static_cast<int>(RTM_PAYLOAD(header));
  for (const rtattr* a = RTM_RTA(body); RTA_OK(a, left); a = RTA_NEXT(a, left)) {
    if (RTA_PAYLOAD(a) < sizeof(std::uint32_t)) continue;
    std::uint32_t value = 0;
    std::memcpy(&value, RTA_DATA(a), sizeof value);
    if (a->rta_type == RTA_DST) route.network = ntohl(value);
    if (a->rta_type == RTA_TABLE) table = value;
    if (a->rta_type == RTA_OIF) route.interface = value;
  }
  if (table != RT_TABLE_LOCAL) return false;
  if (route.prefix == 0) {
    route.network = 0;
  } else if (route.prefix < 32) {
    route.network &= ~(0xFFFFFFFFu >> route.prefix);
  }
  return true;
}

}  // namespace pandarcap
