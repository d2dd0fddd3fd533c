#include "daemon/source/udp_receiver.hpp"

#include <arpa/inet.h>
#include <fmt/format.h>
#include <linux/sock_diag.h>
#include <poll.h>
#include <spdlog/spdlog.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <stdexcept>
#include <string>
#include <system_error>

#include "core/ipv4.hpp"
#include "daemon/allocation_counter.hpp"
#include "daemon/clocks.hpp"
#include "daemon/io/errors.hpp"
#include "daemon/source/udp_port_owner.hpp"
#include "ringbuf/slot_ring.hpp"

namespace pandarcap {
namespace {

constexpr std::size_t kMaxBatch = 1024;
// Room for SO_TIMESTAMPNS (a timespec) and IP_PKTINFO (the destination address), with headers and
// alignment. (Kernel drops are read with SO_MEMINFO on a timer, not from SO_RXQ_OVFL, whose
// count only arrives with the next packet.)
constexpr std::size_t kControlBytes = CMSG_SPACE(sizeof(timespec)) + CMSG_SPACE(sizeof(in_pktinfo));

// The kernel's receive time a control message carries (SO_TIMESTAMPNS), if it is one. The length
// is the kernel's to set, but it is checked before the copy all the same.
std::optional<std::int64_t> kernel_time_ns(const cmsghdr& c) noexcept {
  if (c.cmsg_level != SOL_SOCKET || c.cmsg_type != SCM_TIMESTAMPNS ||
      c.cmsg_len < CMSG_LEN(sizeof(timespec))) {
    return std::nullopt;
  }
  timespec ts{};
  std::memcpy(&ts, CMSG_DATA(&c), sizeof ts);
  return ts.tv_sec * 1'000'000'000LL + ts.tv_nsec;
}

// The limit as text for the warning; a sandbox (systemd's ProtectKernelTunables=/ProcSubset=)
// may hide /proc/sys.
std::string read_rmem_max() {
  std::ifstream in("/proc/sys/net/core/rmem_max");
  std::uint64_t value = 0;
  if (!(in >> value)) return "not readable here";
  return std::to_string(value);
}

}  // namespace

// recvmmsg's headers, allocated with the receiver so nothing is allocated per call; plus the
// scratch slots that overrun datagrams are received into and dropped from.
struct UdpReceiver::Batch {
  std::array<mmsghdr, kMaxBatch> headers{};
  std::array<iovec, kMaxBatch> iov{};
  std::array<std::array<std::uint8_t, kControlBytes>, kMaxBatch> control{};
  std::array<PacketSlot, 16> scratch{};
};

UdpReceiver::UdpReceiver(const UdpReceiverOptions& options)
    : batch_(std::clamp<std::size_t>(options.batch, 1, kMaxBatch)),
      budget_ns_(std::max<std::int64_t>(options.latency_budget_ns, 0)),
      max_wake_datagrams_(options.max_wake_datagrams),
      buffers_(new Batch) {
  empty_at_ns_ = monotonic_ns();  // the socket is new: nothing waits in it from before
  fd_ = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (fd_ < 0) io::throw_errno("cannot create the UDP socket");
  try {
    configure(options);
  } catch (...) {
    ::close(fd_);
    throw;
  }
}

void UdpReceiver::configure(const UdpReceiverOptions& options) {
  const int on = 1;
  // Several listeners may share a multicast port; harmless for unicast.
  if (!options.multicast_ip.empty()) {
    if (::setsockopt(fd_, SOL_SOCKET, SO_REUSEADDR, &on, sizeof on) != 0)
      io::throw_errno("SO_REUSEADDR");
  }

  // Receive buffer: try the privileged variant that ignores rmem_max, then the normal one.
  const int requested =
      static_cast<int>(std::min<std::uint64_t>(options.receive_buffer_bytes, 0x7fffffff));
  if (::setsockopt(fd_, SOL_SOCKET, SO_RCVBUFFORCE, &requested, sizeof requested) != 0 &&
      ::setsockopt(fd_, SOL_SOCKET, SO_RCVBUF, &requested, sizeof requested) != 0) {
    io::throw_errno("cannot set SO_RCVBUF");
  }
  int granted = 0;
  socklen_t length = sizeof granted;
  if (::getsockopt(fd_, SOL_SOCKET, SO_RCVBUF, &granted, &length) != 0)
    io::throw_errno("SO_RCVBUF");
  // The kernel doubles the request for its bookkeeping and reports the doubled size.
  granted_rcvbuf_ = static_cast<std::uint64_t>(granted) / 2;
  if (granted_rcvbuf_ < static_cast<std::uint64_t>(requested)) {
    spdlog::warn(
        "socket receive buffer: {} bytes requested, {} granted: net.core.rmem_max ({}) caps it; "
        "raise it with 'sysctl -w net.core.rmem_max={}' (the package's "
        "/usr/lib/sysctl.d/60-pandarcap.conf does at boot)",
        requested, granted_rcvbuf_, read_rmem_max(), requested);
  } else {
    spdlog::info("socket receive buffer: {} bytes", granted_rcvbuf_);
  }

  // Kernel receive timestamps. Every Linux since 2.6.22 has them; an emulator may not (QEMU's
  // user mode refuses SO_TIMESTAMPNS with ENOPROTOOPT). Without them each datagram gets the time
  // its batch was taken from the socket, later by up to the latency budget: said once, not fatal.
  if (::setsockopt(fd_, SOL_SOCKET, SO_TIMESTAMPNS, &on, sizeof on) != 0) {
    if (errno != ENOPROTOOPT) io::throw_errno("SO_TIMESTAMPNS");
    spdlog::warn(
        "SO_TIMESTAMPNS: not available here (an emulator?): receive times are read when each "
        "batch is taken, so latencies are measured from then, not from arrival");
  }
  // Each datagram's destination address, for the recording: the sensor may send to this host's
  // address, a broadcast or a multicast group, and the file should say which.
  if (::setsockopt(fd_, IPPROTO_IP, IP_PKTINFO, &on, sizeof on) != 0) {
    if (errno != ENOPROTOOPT) io::throw_errno("IP_PKTINFO");
    spdlog::warn(
        "IP_PKTINFO: not available here (an emulator?): the recording gives {} as every "
        "packet's destination",
        options.host_ip);
  }
  const timeval timeout{0, 100'000};
  if (::setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &timeout, sizeof timeout) != 0) {
    io::throw_errno("SO_RCVTIMEO");
  }

  sockaddr_in local{};
  local.sin_family = AF_INET;
  local.sin_port = htons(options.port);
  local.sin_addr = require_ipv4(options.host_ip, "host_ip");
  if (::bind(fd_, reinterpret_cast<const sockaddr*>(&local), sizeof local) != 0) {
    const int error = errno;
    const std::string what =
        "cannot bind UDP " + options.host_ip + ":" + std::to_string(options.port);
    // Who has the port, where /proc tells: the fix is usually to stop them, or to pick another.
    if (error == EADDRINUSE) {
      if (const std::string hint = port_in_use_hint(options.port); !hint.empty()) {
        throw std::runtime_error(fmt::format("{}: {}. {}", what, std::strerror(error), hint));
      }
    }
    io::throw_error(error, what);
  }
  sockaddr_in bound{};
  socklen_t bound_length = sizeof bound;
  if (::getsockname(fd_, reinterpret_cast<sockaddr*>(&bound), &bound_length) != 0) {
    io::throw_errno("getsockname");
  }
  bound_ = bound;  // also each datagram's destination until IP_PKTINFO says otherwise

  if (!options.multicast_ip.empty()) {
    ip_mreq membership{};
    membership.imr_multiaddr = require_ipv4(options.multicast_ip, "multicast_ip");
    membership.imr_interface.s_addr = htonl(INADDR_ANY);
    if (!options.multicast_interface_ip.empty()) {
      membership.imr_interface =
          require_ipv4(options.multicast_interface_ip, "multicast_interface_ip");
    }
    if (::setsockopt(fd_, IPPROTO_IP, IP_ADD_MEMBERSHIP, &membership, sizeof membership) != 0) {
      io::throw_errno("cannot join multicast group " + options.multicast_ip);
    }
    spdlog::info("joined multicast group {}", options.multicast_ip);
  }
  if (!options.sensor_ip.empty()) {
    sources_ = SourceLock(ntohl(require_ipv4(options.sensor_ip, "sensor_ip").s_addr));
  }
  // Kernel drops are read with SO_MEMINFO (Linux 3.19+). Where it is refused (QEMU's user mode)
  // they cannot be counted at all: said at start, since every other stage's drops are counted.
  {
    std::array<std::uint32_t, SK_MEMINFO_VARS> info{};
    socklen_t info_length = sizeof info;
    if (::getsockopt(fd_, SOL_SOCKET, SO_MEMINFO, info.data(), &info_length) != 0) {
      spdlog::warn("SO_MEMINFO: {}: kernel drops (a full socket buffer) cannot be counted here",
                   std::strerror(errno));
    }
  }
  spdlog::info(
      "receiving UDP on {}:{}{}; {}", options.host_ip, bound_port(),
      options.sensor_ip.empty() ? std::string(" from any source") : " from " + options.sensor_ip,
      budget_ns_ == 0 ? std::string("waking for every datagram (latency budget 0)")
                      : fmt::format("latency budget {} ms: the socket is drained in batches",
                                    static_cast<double>(budget_ns_) / 1e6));
}

UdpReceiver::~UdpReceiver() {
  if (fd_ >= 0) ::close(fd_);
}

double UdpReceiver::read_socket_memory(ReceiveCounters& counters) {
  // SO_MEMINFO's drop count is cumulative for the socket's life; the cmsg variant only appears
  // with the next packet after a drop, so this is read on a timer (or at each coalesced wake)
  // instead. The same call says how full the receive buffer is.
  std::array<std::uint32_t, SK_MEMINFO_VARS> info{};
  socklen_t length = sizeof info;
  if (::getsockopt(fd_, SOL_SOCKET, SO_MEMINFO, info.data(), &length) != 0 ||
      length < sizeof(std::uint32_t) * (SK_MEMINFO_DROPS + 1)) {
    return 0.0;
  }
  counters.kernel_drops.store(info[SK_MEMINFO_DROPS] + left_at_stop_, std::memory_order_relaxed);
  if (info[SK_MEMINFO_DROPS] != meminfo_drops_) {
    // Dropped while the buffer was full: they arrived after everything it held, before this
    // read. A packet now, for all this side can tell (the sensor may have stopped since).
    meminfo_drops_ = info[SK_MEMINFO_DROPS];
    counters.note_arrival(monotonic_ns());
  }
  return info[SK_MEMINFO_RCVBUF] == 0 ? 0.0
                                      : static_cast<double>(info[SK_MEMINFO_RMEM_ALLOC]) /
                                            static_cast<double>(info[SK_MEMINFO_RCVBUF]);
}

std::uint64_t UdpReceiver::count_left_at_stop() {
  Batch& batch = *buffers_;
  std::span<PacketSlot> slots = batch.scratch;
  const std::int64_t now_ns = realtime_ns();
  // Bounded whatever the kernel says: a buffer's worth of the smallest datagrams, and then some;
  // and once a datagram came without a timestamp (which could not say it came after the stop),
  // a fifth of a second, against a sender that goes on.
  const std::uint64_t most = granted_rcvbuf_ / 32 + slots.size();
  std::int64_t until_ns = INT64_MAX;
  std::uint64_t left = 0;
  for (std::uint64_t read = 0; read < most && monotonic_ns() < until_ns;) {
    for (std::size_t i = 0; i < slots.size(); ++i) {
      batch.iov[i] = {slots[i].payload, sizeof slots[i].payload};
      msghdr& header = batch.headers[i].msg_hdr;
      header = msghdr{};
      header.msg_iov = &batch.iov[i];
      header.msg_iovlen = 1;
      header.msg_control = batch.control[i].data();
      header.msg_controllen = batch.control[i].size();
    }
    const int received = ::recvmmsg(fd_, batch.headers.data(), static_cast<unsigned>(slots.size()),
                                    MSG_DONTWAIT | MSG_TRUNC, nullptr);
    if (received <= 0) break;  // empty (or an error: nothing more can be read)
    read += static_cast<std::uint64_t>(received);
    for (int i = 0; i < received; ++i) {
      const msghdr& header = batch.headers[i].msg_hdr;
      std::int64_t arrived_ns = 0;
      for (const cmsghdr* c = CMSG_FIRSTHDR(&header); c != nullptr;
           c = CMSG_NXTHDR(const_cast<msghdr*>(&header), const_cast<cmsghdr*>(c))) {
        arrived_ns = kernel_time_ns(*c).value_or(arrived_ns);
      }
      if (arrived_ns == 0 && until_ns == INT64_MAX) until_ns = monotonic_ns() + 200'000'000;
      // One that arrived after this began is past the stop: a sender that goes on sending must
      // not keep the stop here. (It and the rest of its batch are not counted.)
      if (arrived_ns > now_ns) {
        left_at_stop_ += left;
        return left;
      }
      ++left;
    }
    if (static_cast<std::size_t>(received) < slots.size()) break;  // the socket is empty
  }
  left_at_stop_ += left;
  return left;
}

UdpReceiver::Received UdpReceiver::receive_batch(PacketRing& ring, int flags,
                                                 ReceiveCounters& counters) {
  Batch& batch = *buffers_;
  std::span<PacketSlot> slots = ring.reserve(batch_);
  const bool overrun = slots.empty();
  if (overrun) slots = batch.scratch;  // ring full: received and dropped (counted), newest first

  const std::size_t n = slots.size();
  for (std::size_t i = 0; i < n; ++i) {
    PacketSlot& slot = slots[i];
    batch.iov[i] = {slot.payload, sizeof slot.payload};
    msghdr& header = batch.headers[i].msg_hdr;
    header.msg_name = &slot.source.v4;
    header.msg_namelen = sizeof slot.source.v4;
    header.msg_iov = &batch.iov[i];
    header.msg_iovlen = 1;
    header.msg_control = batch.control[i].data();
    header.msg_controllen = batch.control[i].size();
    header.msg_flags = 0;
  }
  // MSG_TRUNC: msg_len is the datagram's real length even when it was longer than the slot,
  // so a cut datagram is recorded with what it had, not as a whole one of the slot's size.
  const std::int64_t before_ns = monotonic_ns();
  const int received =
      ::recvmmsg(fd_, batch.headers.data(), static_cast<unsigned>(n), flags | MSG_TRUNC, nullptr);
  if (received <= 0) {
    if (received < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR) {
      ReceiveCounters::add(counters.receive_errors, 1);
    } else if (received == 0 || errno == EAGAIN || errno == EWOULDBLOCK) {
      empty_at_ns_ = before_ns;
      // Empty until the call gave up (its 100 ms timeout, when it waits): all seen until it
      // returned, which the clock read next stands for (a datagram in between is taken at the
      // next look; the record's hold covers a look that is late).
      counters.note_seen_until(monotonic_ns(), look_interval_ns());
    }
    return {0, n, overrun};
  }

  std::uint64_t bytes = 0;
  std::uint64_t truncated = 0;
  std::uint64_t foreign = 0;
  std::uint64_t other_sensor = 0;
  std::size_t kept = 0;
  const std::int64_t fallback_time = realtime_ns();
  for (int i = 0; i < received; ++i) {
    PacketSlot& slot = slots[i];
    const mmsghdr& message = batch.headers[i];
    bytes += message.msg_len;
    if (overrun) continue;
    slot.original_length = message.msg_len;
    slot.length = std::min<std::uint32_t>(message.msg_len, sizeof slot.payload);
    slot.truncated = (message.msg_hdr.msg_flags & MSG_TRUNC) != 0 || slot.length < message.msg_len;
    truncated += slot.truncated;
    slot.receive_time_ns = fallback_time;
    slot.destination.v4 = bound_;
    slot.wire_header_length = 0;
    for (cmsghdr* c = CMSG_FIRSTHDR(&message.msg_hdr); c != nullptr;
         c = CMSG_NXTHDR(const_cast<msghdr*>(&message.msg_hdr), c)) {
      if (const std::optional<std::int64_t> time = kernel_time_ns(*c)) {
        slot.receive_time_ns = *time;
      } else if (c->cmsg_level == IPPROTO_IP && c->cmsg_type == IP_PKTINFO &&
                 c->cmsg_len >= CMSG_LEN(sizeof(in_pktinfo))) {
        in_pktinfo info{};
        std::memcpy(&info, CMSG_DATA(c), sizeof info);
        slot.destination.v4.sin_addr = info.ipi_addr;
      }
    }
    const SourceLock::Verdict verdict = sources_.judge(
        ntohl(slot.source.v4.sin_addr.s_addr), ntohs(slot.source.v4.sin_port),
        std::span<const std::uint8_t>(slot.payload, slot.length), slot.receive_time_ns);
    if (verdict != SourceLock::Verdict::kSensor) {
      ++foreign;
      other_sensor += verdict == SourceLock::Verdict::kOtherSensor;
      continue;
    }
    // Keep accepted datagrams contiguous; a copy happens only after a foreign one.
    if (kept != static_cast<std::size_t>(i)) slots[kept] = slot;
    ++kept;
  }
  // When the newest kept datagram arrived (an overrun's, dropped, arrived just now): the
  // health's last packet. Then, a batch that came back short found the socket empty.
  const std::int64_t now_mono = monotonic_ns();
  if (overrun) {
    counters.note_arrival(now_mono);
  } else if (kept > 0) {
    counters.note_arrival(arrival_on_monotonic(slots[kept - 1].receive_time_ns, realtime_ns(),
                                               now_mono, empty_at_ns_, 0));
  }
  if (static_cast<std::size_t>(received) < n) {
    empty_at_ns_ = before_ns;
    // Drained: everything that arrived before is seen, but for what the kernel dropped while the
    // buffer was full (read here, every 10 ms at most: the drops' arrival is noted).
    if (now_mono >= next_drop_look_ns_) {
      read_socket_memory(counters);
      next_drop_look_ns_ = now_mono + 10'000'000;
    }
    counters.note_seen_until(before_ns, look_interval_ns());
  }
  ReceiveCounters::add(counters.datagrams, static_cast<std::uint64_t>(received));
  ReceiveCounters::add(counters.bytes, bytes);
  if (overrun) {
    ReceiveCounters::add(counters.ring_overruns, static_cast<std::uint64_t>(received));
  } else {
    ReceiveCounters::add(counters.truncated, truncated);
    ReceiveCounters::add(counters.foreign, foreign);
    ReceiveCounters::add(counters.other_sensor, other_sensor);
    counters.publish_sources(sources_.sensor_source(), sources_.other_source(),
                             sources_.source_changes());
    if (kept > 0) ring.publish(kept);
  }
  return {static_cast<std::size_t>(received), n, overrun, overrun ? 0 : kept};
}

void UdpReceiver::run(PacketRing& ring, const std::atomic<bool>& stop, ReceiveCounters& counters,
                      std::atomic<std::uint64_t>& heartbeat) {
  if (budget_ns_ == 0) {
    run_per_datagram(ring, stop, counters, heartbeat);
  } else {
    run_coalesced(ring, stop, counters, heartbeat);
  }
  alloc::mark_this_thread_cold();  // the stop's logging may allocate
  // A backlog longer than the stop's drain: what it did not reach is counted, not left in no
  // counter when the socket closes.
  if (const std::uint64_t left = count_left_at_stop(); left > 0) {
    spdlog::warn(
        "UDP socket: the stop's drain ended with {} datagrams still in the socket's buffer (a "
        "backlog longer than it takes): counted as kernel drops",
        left);
  }
  read_socket_memory(counters);  // the last drops, for the final health
}

namespace {

// On stop, what the socket already holds is still taken (without waiting, for at most kDrainNs
// against a sender that does not stop): datagrams the kernel accepted are then either received
// or counted as dropped, none left uncounted in the buffer.
constexpr std::int64_t kDrainNs = 200'000'000;

}  // namespace

void UdpReceiver::run_per_datagram(PacketRing& ring, const std::atomic<bool>& stop,
                                   ReceiveCounters& counters,
                                   std::atomic<std::uint64_t>& heartbeat) {
  std::int64_t next_meminfo_ns = 0;
  const std::int64_t warm_ns = coarse_monotonic_ns() + kWarmUpNs;
  bool hot = false;
  std::int64_t drain_until = 0;  // 0: not stopping
  for (;;) {
    if (drain_until == 0 && stop.load(std::memory_order_relaxed)) {
      const std::int64_t stopped_ns = coarse_monotonic_ns();
      counters.note_stop(stopped_ns);
      drain_until = stopped_ns + kDrainNs;
    }
    const bool draining = drain_until != 0;
    if (draining && coarse_monotonic_ns() >= drain_until) break;
    ReceiveCounters::add(heartbeat, 1);
    const std::int64_t now = coarse_monotonic_ns();
    if (!hot && now >= warm_ns) {
      alloc::mark_this_thread_hot(alloc::HotThread::kReceive);
      hot = true;
    }
    if (now >= next_meminfo_ns) {
      read_socket_memory(counters);
      next_meminfo_ns = now + 1'000'000'000;
    }
    if (ring.size_approx() == ring.capacity()) {
      // Ring full. Wait (briefly) for a datagram, then drop what is waiting and count it.
      pollfd pfd{fd_, POLLIN, 0};
      const int ready = ::poll(&pfd, 1, draining ? 0 : 1);
      // Nothing came while it waited: the socket is seen empty (the decoder is behind, not this
      // thread), and a silence then is the sensor's.
      if (ready == 0) counters.note_seen_until(monotonic_ns(), look_interval_ns());
      if (ready <= 0) {
        if (draining) break;
        continue;
      }
    }
    // Blocks until a datagram (or the 100 ms SO_RCVTIMEO): each return is a wake-up.
    const Received r =
        receive_batch(ring, MSG_WAITFORONE | (draining ? MSG_DONTWAIT : 0), counters);
    ReceiveCounters::add(counters.wakeups, 1);
    if (r.received == 0) {
      if (draining) break;  // the socket is empty
      continue;             // timeout: check the stop flag
    }
    if (r.published > 0) ring.notify();
  }
}

void UdpReceiver::run_coalesced(PacketRing& ring, const std::atomic<bool>& stop,
                                ReceiveCounters& counters, std::atomic<std::uint64_t>& heartbeat) {
  const std::int64_t warm_ns = monotonic_ns() + kWarmUpNs;
  bool hot = false;
  std::int64_t drain_until = 0;  // 0: not stopping
  // From the shortest sleep up (x2 per wake): the first sleeps measure the rate before a long
  // one could overflow a small buffer.
  std::int64_t sleep_ns = kMinSleepNs;
  for (;;) {
    const std::int64_t wake_ns = monotonic_ns();
    if (drain_until == 0 && stop.load(std::memory_order_relaxed)) {
      counters.note_stop(wake_ns);
      drain_until = wake_ns + kDrainNs;
    }
    const bool draining = drain_until != 0;
    ReceiveCounters::add(heartbeat, 1);
    ReceiveCounters::add(counters.wakeups, 1);
    if (!hot && wake_ns >= warm_ns) {
      alloc::mark_this_thread_hot(alloc::HotThread::kReceive);
      hot = true;
    }
    // How full the buffer got while this thread slept (and the kernel's drop count).
    double fill = read_socket_memory(counters);

    // Drain: full batches until one comes back short (the socket is empty), then one wake-up
    // of the decoder for all of it.
    std::size_t published = 0;
    std::size_t received = 0;
    for (;;) {
      const Received r = receive_batch(ring, MSG_DONTWAIT, counters);
      published += r.published;
      received += r.received;
      if (r.received < r.requested) break;
      if (draining && monotonic_ns() >= drain_until) break;
    }
    if (published > 0) ring.notify();
    if (draining) break;  // drained once after the stop: everything the kernel took is counted

    // The next sleep: as long as the budget allows, but short enough that, at the rate the
    // buffer filled during the last one, it would be at most kTargetFill full at the next wake
    // (bursts of several times that rate still fit), and that a wake takes at most
    // max_wake_datagrams (counted as that fill). Grows back at most 2x per wake.
    if (max_wake_datagrams_ > 0) {
      fill = std::max(fill, kTargetFill * static_cast<double>(received) /
                                static_cast<double>(max_wake_datagrams_));
    }
    if (fill > kTargetFill) {
      sleep_ns = static_cast<std::int64_t>(static_cast<double>(sleep_ns) * kTargetFill / fill);
    } else {
      sleep_ns *= 2;
    }
    sleep_ns = std::clamp(sleep_ns, kMinSleepNs, budget_ns_);
    const std::int64_t deadline = wake_ns + sleep_ns;
    const timespec ts{static_cast<time_t>(deadline / 1'000'000'000),
                      static_cast<long>(deadline % 1'000'000'000)};
    clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr);  // EINTR: wakes early, fine
  }
}

}  // namespace pandarcap
