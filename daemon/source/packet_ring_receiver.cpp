#include "daemon/source/packet_ring_receiver.hpp"

#include <arpa/inet.h>
#include <fmt/format.h>
#include <linux/filter.h>
#include <net/ethernet.h>
#include <net/if.h>
#include <pcap/pcap.h>
#include <poll.h>
#include <spdlog/spdlog.h>
#include <sys/mman.h>
#include <sys/socket.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <memory>
#include <stdexcept>
#include <string>

#include "core/ipv4.hpp"
#include "daemon/allocation_counter.hpp"
#include "daemon/clocks.hpp"
#include "daemon/io/errors.hpp"

namespace pandarcap {
namespace {

constexpr std::uint16_t kEthertypeIpv4 = 0x0800;
constexpr std::uint16_t kEthertypeVlan = 0x8100;  // 802.1Q
constexpr std::uint16_t kEthertypeQinQ = 0x88A8;  // 802.1ad
constexpr std::size_t kEthernetBytes = 14;
constexpr std::size_t kUdpBytes = 8;

std::uint16_t load_be16(const std::uint8_t* p) noexcept {
  return static_cast<std::uint16_t>(p[0] << 8 | p[1]);
}

void store_be16(std::uint8_t* p, std::uint16_t v) noexcept {
  p[0] = static_cast<std::uint8_t>(v >> 8);
  p[1] = static_cast<std::uint8_t>(v);
}

[[noreturn]] void throw_packet_socket_error(int error, std::string_view what) {
  if (error == EPERM || error == EACCES) {
    throw MissingCapability(fmt::format(
        "{}: {}: input.receiver = \"packet_ring\" needs the CAP_NET_RAW capability. Run as root, "
        "or under systemd with the drop-in /usr/share/pandarcap/examples/"
        "pandarcapd-packet-ring.conf (systemd/ in the source) installed as "
        "/etc/systemd/system/pandarcapd@NAME.service.d/packet-ring.conf "
        "(AmbientCapabilities=CAP_NET_RAW; docs/deploy.md), or use input.receiver = \"socket\", "
        "which needs no privilege",
        what, std::strerror(error)));
  }
  io::throw_error(error, what);
}

// "udp dst port N" as a classic BPF program for Ethernet frames, from libpcap's compiler.
struct CompiledFilter {
  bpf_program program{};
  ~CompiledFilter() { pcap_freecode(&program); }
};

void attach_port_filter(int fd, std::uint16_t port) {
  std::unique_ptr<pcap_t, decltype(&pcap_close)> dead(pcap_open_dead(DLT_EN10MB, 262144),
                                                      &pcap_close);
  if (!dead) throw std::runtime_error("pcap_open_dead failed");
  const std::string expression = fmt::format("udp dst port {}", port);
  CompiledFilter filter;
  if (pcap_compile(dead.get(), &filter.program, expression.c_str(), 1, PCAP_NETMASK_UNKNOWN) != 0) {
    throw std::runtime_error(
        fmt::format("cannot compile the filter \"{}\": {}", expression, pcap_geterr(dead.get())));
  }
  // libpcap's bpf_insn and the kernel's sock_filter are the same four fields.
  static_assert(sizeof(bpf_insn) == sizeof(sock_filter));
  sock_fprog program{static_cast<unsigned short>(filter.program.bf_len),
                     reinterpret_cast<sock_filter*>(filter.program.bf_insns)};
  if (::setsockopt(fd, SOL_SOCKET, SO_ATTACH_FILTER, &program, sizeof program) != 0) {
    io::throw_errno("cannot attach the filter \"" + expression + "\"");
  }
}

void attach_drop_all(int fd) {
  sock_filter drop{BPF_RET | BPF_K, 0, 0, 0};
  sock_fprog program{1, &drop};
  if (::setsockopt(fd, SOL_SOCKET, SO_ATTACH_FILTER, &program, sizeof program) != 0) {
    io::throw_errno("cannot attach a drop-all filter to the UDP socket on the data port");
  }
}

}  // namespace

// One packet as the block holds it, parsed: what the slot and the source lock need.
struct PacketRingReceiver::Frame {
  const std::uint8_t* payload = nullptr;
  std::uint32_t kept = 0;          // payload bytes in the block
  std::uint32_t original = 0;      // the datagram's length by its UDP header
  bool truncated = false;          // the block holds less than the datagram (or a first fragment)
  std::uint32_t header_bytes = 0;  // Ethernet (+ tags) + IPv4 + UDP, as in the block
  const std::uint8_t* mac = nullptr;
  sockaddr_in source{};
  sockaddr_in destination{};
};

PacketRingReceiver::PacketRingReceiver(const UdpReceiverOptions& options) {
  if (options.interface.empty()) {
    throw std::runtime_error(
        "input.receiver = \"packet_ring\" needs sensor.interface (--interface IFACE)");
  }
  if (!options.sensor_ip.empty()) {
    sources_ = SourceLock(ntohl(require_ipv4(options.sensor_ip, "sensor_ip").s_addr));
  }
  open_guard(options);
  open_ring(options);
}

PacketRingReceiver::~PacketRingReceiver() {
  if (map_ != nullptr) ::munmap(map_, std::size_t{block_bytes_} * block_count_);
}

void PacketRingReceiver::open_guard(const UdpReceiverOptions& options) {
  guard_ = io::UniqueFd(::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0));
  if (!guard_) io::throw_errno("cannot create the UDP socket that keeps the data port");
  attach_drop_all(guard_.get());
  // Asking for receive timestamps on any socket makes the kernel stamp every frame as it
  // arrives (net_enable_timestamp), before any tap: the ring's times are then the arrival's,
  // the same ones tcpdump records, not each socket's own later reading of the clock.
  const int on = 1;
  ::setsockopt(guard_.get(), SOL_SOCKET, SO_TIMESTAMPNS, &on, sizeof on);
  const int smallest = 1;  // the kernel rounds it up to its minimum: it never holds a datagram
  ::setsockopt(guard_.get(), SOL_SOCKET, SO_RCVBUF, &smallest, sizeof smallest);
  if (!options.multicast_ip.empty()) {
    ::setsockopt(guard_.get(), SOL_SOCKET, SO_REUSEADDR, &on, sizeof on);
  }
  sockaddr_in local{};
  local.sin_family = AF_INET;
  local.sin_port = htons(options.port);
  local.sin_addr = require_ipv4(options.host_ip, "host_ip");
  if (::bind(guard_.get(), reinterpret_cast<const sockaddr*>(&local), sizeof local) != 0) {
    // Another socket has the port: it already keeps the kernel from answering, so none is
    // needed; but a free port cannot be chosen then.
    if (errno != EADDRINUSE || options.port == 0) {
      io::throw_errno(
          fmt::format("cannot bind UDP {}:{} (the socket that keeps the host from "
                      "answering the sensor's datagrams with ICMP)",
                      options.host_ip, options.port));
    }
    spdlog::info("UDP port {} is already bound by another socket: it answers for this host",
                 options.port);
    guard_.reset();
    port_ = options.port;
  } else {
    sockaddr_in bound{};
    socklen_t length = sizeof bound;
    if (::getsockname(guard_.get(), reinterpret_cast<sockaddr*>(&bound), &length) != 0) {
      io::throw_errno("getsockname");
    }
    port_ = ntohs(bound.sin_port);
  }
  if (guard_ && !options.multicast_ip.empty()) {
    ip_mreq membership{};
    membership.imr_multiaddr = require_ipv4(options.multicast_ip, "multicast_ip");
    membership.imr_interface.s_addr = htonl(INADDR_ANY);
    if (!options.multicast_interface_ip.empty()) {
      membership.imr_interface =
          require_ipv4(options.multicast_interface_ip, "multicast_interface_ip");
    }
    if (::setsockopt(guard_.get(), IPPROTO_IP, IP_ADD_MEMBERSHIP, &membership, sizeof membership) !=
        0) {
      io::throw_errno("cannot join multicast group " + options.multicast_ip);
    }
  }
}

void PacketRingReceiver::open_ring(const UdpReceiverOptions& options) {
  const unsigned index = ::if_nametoindex(options.interface.c_str());
  if (index == 0) {
    throw NoSuchInterface(fmt::format(
        "sensor.interface \"{}\": no such network interface here (`ip link` lists them)",
        options.interface));
  }
  // Protocol 0: the socket takes no frame until it is bound below, after its filter and ring.
  fd_ = io::UniqueFd(::socket(AF_PACKET, SOCK_RAW | SOCK_CLOEXEC, 0));
  if (!fd_) throw_packet_socket_error(errno, "cannot create the AF_PACKET socket");
  attach_port_filter(fd_.get(), port_);

  const int version = TPACKET_V3;
  if (::setsockopt(fd_.get(), SOL_PACKET, PACKET_VERSION, &version, sizeof version) != 0) {
    io::throw_errno("PACKET_VERSION TPACKET_V3");
  }
  // This host's own frames (each loopback datagram passes the interface twice): not wanted.
  // Linux 4.20+; older kernels are covered by the packet type check in take_block().
  const int on = 1;
  ::setsockopt(fd_.get(), SOL_PACKET, PACKET_IGNORE_OUTGOING, &on, sizeof on);

  block_count_ = std::max<std::uint32_t>(
      kMinBlocks, static_cast<std::uint32_t>(std::min<std::uint64_t>(
                      options.receive_buffer_bytes / kBlockBytes, 1u << 16)));
  const std::int64_t budget_ms = options.latency_budget_ns / 1'000'000;
  retire_ms_ = static_cast<std::uint32_t>(std::clamp<std::int64_t>(budget_ms, 1, 1000));
  tpacket_req3 request{};
  request.tp_block_size = block_bytes_;
  request.tp_block_nr = block_count_;
  request.tp_frame_size = kFrameBytes;
  request.tp_frame_nr = block_bytes_ / kFrameBytes * block_count_;
  request.tp_retire_blk_tov = retire_ms_;
  if (::setsockopt(fd_.get(), SOL_PACKET, PACKET_RX_RING, &request, sizeof request) != 0) {
    io::throw_errno(fmt::format("cannot set up a TPACKET_V3 ring of {} blocks of {} bytes",
                                block_count_, block_bytes_));
  }
  const std::size_t bytes = std::size_t{block_bytes_} * block_count_;
  void* map =
      ::mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_SHARED | MAP_POPULATE, fd_.get(), 0);
  if (map == MAP_FAILED) io::throw_errno("cannot map the packet ring");
  map_ = map;

  sockaddr_ll link{};
  link.sll_family = AF_PACKET;
  link.sll_protocol = htons(ETH_P_ALL);
  link.sll_ifindex = static_cast<int>(index);
  if (::bind(fd_.get(), reinterpret_cast<const sockaddr*>(&link), sizeof link) != 0) {
    io::throw_errno("cannot bind the packet socket to " + options.interface);
  }
  // What the filter let in before the ring existed is none: the protocol was 0 until the bind.
  spdlog::info(
      "receiving UDP port {} on {} through a TPACKET_V3 ring ({} blocks of {} KiB, handed over "
      "when full or after {} ms){}",
      port_, options.interface, block_count_, block_bytes_ / 1024, retire_ms_,
      options.sensor_ip.empty() ? std::string(" from any source") : " from " + options.sensor_ip);
}

tpacket_block_desc* PacketRingReceiver::ready_block() noexcept {
  auto* block = reinterpret_cast<tpacket_block_desc*>(static_cast<std::uint8_t*>(map_) +
                                                      std::size_t{next_block_} * block_bytes_);
  // acquire: the packets the kernel wrote into the block happen before its status says so.
  const std::uint32_t status = __atomic_load_n(&block->hdr.bh1.block_status, __ATOMIC_ACQUIRE);
  return (status & TP_STATUS_USER) != 0 ? block : nullptr;
}

namespace {

// Parses the frame at `mac` (Ethernet, in-band VLAN tags, IPv4, UDP). False for anything the
// filter should not have passed (it is skipped).
bool parse_frame(const std::uint8_t* mac, std::uint32_t captured, std::uint32_t wire_length,
                 const std::uint8_t*& udp_payload, std::uint32_t& header_bytes, std::uint32_t& kept,
                 std::uint32_t& original, bool& truncated, sockaddr_in& source,
                 sockaddr_in& destination) noexcept {
  std::size_t offset = 12;
  if (captured < kEthernetBytes) return false;
  std::uint16_t ethertype = load_be16(mac + offset);
  // Tags still in the frame (the kernel takes the outer one into tp_vlan_tci).
  for (int tags = 0; (ethertype == kEthertypeVlan || ethertype == kEthertypeQinQ) && tags < 2;
       ++tags) {
    offset += 4;
    if (captured < offset + 2) return false;
    ethertype = load_be16(mac + offset);
  }
  offset += 2;
  if (ethertype != kEthertypeIpv4 || captured < offset + 20) return false;
  const std::uint8_t* ip = mac + offset;
  const std::size_t ihl = std::size_t{ip[0] & 0x0Fu} * 4;
  if ((ip[0] >> 4) != 4 || ihl < 20 || ip[9] != 17 || captured < offset + ihl + kUdpBytes) {
    return false;
  }
  const std::uint16_t fragment = load_be16(ip + 6);
  if ((fragment & 0x1FFF) != 0) return false;  // not the first fragment: no UDP header
  const std::uint8_t* udp = ip + ihl;
  const std::uint16_t udp_length = load_be16(udp + 4);
  header_bytes = static_cast<std::uint32_t>(offset + ihl + kUdpBytes);
  original = udp_length >= kUdpBytes ? udp_length - static_cast<std::uint32_t>(kUdpBytes) : 0;
  kept = std::min(original, captured - header_bytes);
  // More fragments follow, or the block (or the wire) holds less than the UDP length says.
  truncated = (fragment & 0x2000) != 0 || kept < original || wire_length < header_bytes + original;
  udp_payload = udp + kUdpBytes;
  source = {};
  source.sin_family = AF_INET;
  std::memcpy(&source.sin_addr.s_addr, ip + 12, 4);
  std::memcpy(&source.sin_port, udp, 2);
  destination = {};
  destination.sin_family = AF_INET;
  std::memcpy(&destination.sin_addr.s_addr, ip + 16, 4);
  std::memcpy(&destination.sin_port, udp + 2, 2);
  return true;
}

}  // namespace

void PacketRingReceiver::take_block(tpacket_block_desc& block, PacketRing& ring,
                                    ReceiveCounters& counters) {
  const std::uint32_t count = block.hdr.bh1.num_pkts;
  const auto* base = reinterpret_cast<const std::uint8_t*>(&block);
  std::uint32_t offset = block.hdr.bh1.offset_to_first_pkt;
  std::uint64_t datagrams = 0, bytes = 0, truncated = 0, foreign = 0, other_sensor = 0;
  std::uint64_t overruns = 0;
  std::span<PacketSlot> slots;
  std::size_t filled = 0;
  std::size_t published = 0;
  for (std::uint32_t i = 0; i < count && offset != 0 && offset < block_bytes_; ++i) {
    const auto* header = reinterpret_cast<const tpacket3_hdr*>(base + offset);
    const std::uint32_t next = header->tp_next_offset;
    const auto* link = reinterpret_cast<const sockaddr_ll*>(
        reinterpret_cast<const std::uint8_t*>(header) + TPACKET_ALIGN(sizeof(tpacket3_hdr)));
    const std::uint32_t mac_offset = offset + header->tp_mac;
    offset = next == 0 ? 0 : offset + next;
    // Sent by this host, or addressed to another one: no UDP socket here would have had it.
    if (link->sll_pkttype == PACKET_OUTGOING || link->sll_pkttype == PACKET_OTHERHOST) continue;
    if (mac_offset + std::uint64_t{header->tp_snaplen} > block_bytes_) continue;  // never
    const std::uint8_t* mac = base + mac_offset;
    Frame f;
    if (!parse_frame(mac, header->tp_snaplen, header->tp_len, f.payload, f.header_bytes, f.kept,
                     f.original, f.truncated, f.source, f.destination)) {
      continue;
    }
    ++datagrams;
    bytes += f.original;
    if (filled == slots.size()) {
      if (filled > 0) {
        ring.publish(filled);
        published += filled;
      }
      slots = ring.reserve(count - i);
      filled = 0;
    }
    if (slots.empty()) {
      ++overruns;  // the decoder is behind: dropped, newest first, counted
      continue;
    }
    PacketSlot& slot = slots[filled];
    slot.length = std::min<std::uint32_t>(f.kept, sizeof slot.payload);
    std::memcpy(slot.payload, f.payload, slot.length);
    slot.original_length = f.original;
    slot.truncated = f.truncated || slot.length < f.original;
    slot.receive_time_ns =
        std::int64_t{header->tp_sec} * 1'000'000'000 + std::int64_t{header->tp_nsec};
    slot.source.v4 = f.source;
    slot.destination.v4 = f.destination;
    // The headers as they were on the wire: the tag the kernel took out goes back after the
    // MAC addresses, with its own TPID (802.1Q unless the kernel says otherwise).
    const bool tagged = (header->tp_status & TP_STATUS_VLAN_VALID) != 0;
    const std::size_t wire_bytes = f.header_bytes + (tagged ? 4 : 0);
    if (wire_bytes <= kWireHeaderCapacity) {
      std::uint8_t* out = slot.wire_header;
      std::memcpy(out, mac, 12);
      std::size_t at = 12;
      if (tagged) {
        const std::uint16_t tpid = (header->tp_status & TP_STATUS_VLAN_TPID_VALID) != 0
                                       ? header->hv1.tp_vlan_tpid
                                       : kEthertypeVlan;
        store_be16(out + 12, tpid);
        store_be16(out + 14, static_cast<std::uint16_t>(header->hv1.tp_vlan_tci));
        at = 16;
      }
      std::memcpy(out + at, mac + 12, f.header_bytes - 12);
      slot.wire_header_length = static_cast<std::uint8_t>(wire_bytes);
    } else {
      slot.wire_header_length = 0;  // recorded with synthesised headers
    }
    truncated += slot.truncated;
    const SourceLock::Verdict verdict = sources_.judge(
        ntohl(f.source.sin_addr.s_addr), ntohs(f.source.sin_port),
        std::span<const std::uint8_t>(slot.payload, slot.length), slot.receive_time_ns);
    if (verdict != SourceLock::Verdict::kSensor) {
      ++foreign;
      other_sensor += verdict == SourceLock::Verdict::kOtherSensor;
      continue;  // the slot is filled again by the next datagram
    }
    ++filled;
  }
  if (filled > 0) {
    ring.publish(filled);
    published += filled;
  }
  // release: the kernel may write the block again once every read of it is done.
  __atomic_store_n(&block.hdr.bh1.block_status, TP_STATUS_KERNEL, __ATOMIC_RELEASE);
  next_block_ = (next_block_ + 1) % block_count_;

  ReceiveCounters::add(counters.datagrams, datagrams);
  ReceiveCounters::add(counters.bytes, bytes);
  ReceiveCounters::add(counters.truncated, truncated);
  ReceiveCounters::add(counters.foreign, foreign);
  ReceiveCounters::add(counters.other_sensor, other_sensor);
  ReceiveCounters::add(counters.ring_overruns, overruns);
  counters.publish_sources(sources_.sensor_source(), sources_.other_source(),
                           sources_.source_changes());
  if (published > 0) ring.notify();
}

void PacketRingReceiver::read_statistics(ReceiveCounters& counters) noexcept {
  tpacket_stats_v3 stats{};
  socklen_t length = sizeof stats;
  if (::getsockopt(fd_.get(), SOL_PACKET, PACKET_STATISTICS, &stats, &length) != 0) return;
  // Each read returns the counts since the last one (and resets them): added up here.
  kernel_drops_ += stats.tp_drops;
  queue_freezes_ += stats.tp_freeze_q_cnt;
  counters.kernel_drops.store(kernel_drops_, std::memory_order_relaxed);
}

void PacketRingReceiver::run(PacketRing& ring, const std::atomic<bool>& stop,
                             ReceiveCounters& counters, std::atomic<std::uint64_t>& heartbeat) {
  const std::int64_t warm_ns = coarse_monotonic_ns() + kWarmUpNs;
  bool hot = false;
  std::int64_t next_statistics_ns = 0;
  // On stop the block being filled is handed over by its retire timer at the latest: waiting
  // for that (twice its period) takes every frame the kernel accepted before the stop.
  const std::int64_t drain_ns = std::max<std::int64_t>(200'000'000, 3'000'000LL * retire_ms_);
  std::int64_t drain_until = 0;
  for (;;) {
    const std::int64_t now = coarse_monotonic_ns();
    if (drain_until == 0 && stop.load(std::memory_order_relaxed)) drain_until = now + drain_ns;
    const bool draining = drain_until != 0;
    if (draining && now >= drain_until) break;
    ReceiveCounters::add(heartbeat, 1);
    if (!hot && now >= warm_ns) {
      alloc::mark_this_thread_hot(alloc::HotThread::kReceive);
      hot = true;
    }
    if (now >= next_statistics_ns) {
      read_statistics(counters);
      next_statistics_ns = now + 1'000'000'000;
    }
    if (tpacket_block_desc* block = ready_block()) {
      take_block(*block, ring, counters);
      continue;
    }
    // No block ready: sleep until the kernel hands one over (full, or its timer ran out).
    pollfd pfd{fd_.get(), POLLIN | POLLERR, 0};
    const int timeout_ms = draining ? static_cast<int>(2 * retire_ms_ + 1) : 100;
    const int ready = ::poll(&pfd, 1, timeout_ms);
    ReceiveCounters::add(counters.wakeups, 1);
    if (ready < 0 && errno != EINTR) ReceiveCounters::add(counters.receive_errors, 1);
    if (ready == 0 && draining && ready_block() == nullptr) break;  // nothing more is coming
  }
  read_statistics(counters);  // the last drops, for the final health
  if (queue_freezes_ > 0) {
    spdlog::warn("packet ring: the kernel found no free block {} times ({} frames dropped)",
                 queue_freezes_, kernel_drops_);
  }
  alloc::mark_this_thread_cold();
}

}  // namespace pandarcap
