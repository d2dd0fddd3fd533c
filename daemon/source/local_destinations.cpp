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

LocalDestinations::LocalDestinations()
    : fd_(::socket(AF_NETLINK, SOCK_RAW | SOCK_NONBLOCK | SOCK_CLOEXEC, NETLINK_ROUTE)) {
  if (!fd_) io::throw_errno("netlink socket (this host's local routes)");
  sockaddr_nl local{};
  local.nl_family = AF_NETLINK;
  local.nl_groups = RTMGRP_IPV4_ROUTE;
  if (::bind(fd_.get(), reinterpret_cast<const sockaddr*>(&local), sizeof local) != 0)
    io::throw_errno("netlink bind (this host's local routes)");
  if (!request_dump()) io::throw_errno("netlink RTM_GETROUTE (this host's local routes)");
  read_messages(/*wait_for_dump=*/true);
}

bool LocalDestinations::contains(std::uint32_t destination) const noexcept {
  if (overflow_) return true;
  const auto end = routes_.begin() + static_cast<std::ptrdiff_t>(count_);
  return std::any_of(routes_.begin(), end, [&](const Route& r) {
    return r.prefix == 0 || ((destination ^ r.network) >> (32 - r.prefix)) == 0;
  });
}

bool LocalDestinations::request_dump() noexcept {
  struct {
    nlmsghdr header;
    rtmsg body;
  } request{};
  request.header.nlmsg_len = sizeof request;
  request.header.nlmsg_type = RTM_GETROUTE;
  request.header.nlmsg_flags = NLM_F_REQUEST | NLM_F_DUMP;
  request.header.nlmsg_seq = ++dump_sequence_;
  request.body.rtm_family = AF_INET;
  sockaddr_nl kernel{};
  kernel.nl_family = AF_NETLINK;
  return ::sendto(fd_.get(), &request, sizeof request, 0, reinterpret_cast<sockaddr*>(&kernel),
                  sizeof kernel) == static_cast<ssize_t>(sizeof request);
}

void LocalDestinations::refresh() noexcept {
  read_messages(/*wait_for_dump=*/false);
}

void LocalDestinations::read_messages(bool wait_for_dump) noexcept {
  // Start-up only: the kernel answers a dump at once; two seconds is a bound, not a wait.
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(2);
  bool dump_done = !wait_for_dump;
  for (;;) {
    const ssize_t n = ::recv(fd_.get(), buffer_.data(), buffer_.size(), MSG_DONTWAIT);
    if (n < 0) {
      if (errno == EINTR) continue;
      if (errno == ENOBUFS) {
        // Changes were lost: the table can no longer be trusted. It is read whole again, and
        // until it is, nothing is refused.
        count_ = 0;
        overflow_ = true;
        if (request_dump()) {
          overflow_ = false;
          dump_done = false;
          continue;
        }
        return;
      }
      if (dump_done || std::chrono::steady_clock::now() >= give_up) return;
      pollfd pfd{fd_.get(), POLLIN, 0};
      ::poll(&pfd, 1, 100);
      continue;
    }
    auto left = static_cast<unsigned>(n);
    for (auto* h = reinterpret_cast<const nlmsghdr*>(buffer_.data()); NLMSG_OK(h, left);
         h = NLMSG_NEXT(h, left)) {
      if (h->nlmsg_type == NLMSG_DONE || h->nlmsg_type == NLMSG_ERROR) dump_done = true;
      if (h->nlmsg_type == RTM_NEWROUTE || h->nlmsg_type == RTM_DELROUTE) apply(h);
    }
  }
}

void LocalDestinations::apply(const void* message) noexcept {
  const auto* header = static_cast<const nlmsghdr*>(message);
  if (header->nlmsg_len < NLMSG_LENGTH(sizeof(rtmsg))) return;
  const auto* body = static_cast<const rtmsg*>(NLMSG_DATA(header));
  if (body->rtm_family != AF_INET || body->rtm_dst_len > 32) return;
  if (body->rtm_type != RTN_LOCAL && body->rtm_type != RTN_BROADCAST) return;
  std::uint32_t table = body->rtm_table;
  Route route;
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
  if (table != RT_TABLE_LOCAL) return;
  if (route.prefix < 32) {
    route.network = route.prefix == 0 ? 0 : route.network & ~(0xFFFFFFFFu >> route.prefix);
  }
  if (header->nlmsg_type == RTM_NEWROUTE) {
    add(route);
  } else {
    remove(route);
  }
}

void LocalDestinations::add(const Route& route) noexcept {
  const auto end = routes_.begin() + static_cast<std::ptrdiff_t>(count_);
  if (std::find(routes_.begin(), end, route) != end) return;
  if (count_ == routes_.size()) {
    if (!overflow_) {
      spdlog::warn(
          "packet ring: this host's local routing table has more than {} routes: a datagram to "
          "any address that reaches the interface with its MAC is taken",
          kMaxRoutes);
    }
    overflow_ = true;
    return;
  }
  routes_[count_++] = route;
}

void LocalDestinations::remove(const Route& route) noexcept {
  const auto end = routes_.begin() + static_cast<std::ptrdiff_t>(count_);
  const auto it = std::find(routes_.begin(), end, route);
  if (it == end) return;
  *it = routes_[--count_];
}

}  // namespace pandarcap
