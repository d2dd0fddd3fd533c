#include "daemon/source/packet_ring_receiver.hpp"

#include <arpa/inet.h>
#include <fmt/format.h>
#include <linux/filter.h>
#include <net/ethernet.h>
#include <net/if.h>
#include <net/if_arp.h>
#include <pcap/pcap.h>
#include <poll.h>
#include <spdlog/spdlog.h>
#include <sys/mman.h>
#include <sys/socket.h>

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cstring>
#include <memory>
#include <stdexcept>
#include <string>

#include "core/ipv4.hpp"
#include "core/wire_frame.hpp"
#include "daemon/allocation_counter.hpp"
#include "daemon/clocks.hpp"
#include "daemon/io/errors.hpp"
#include "daemon/io/text_file.hpp"
#include "daemon/source/udp_port_owner.hpp"

namespace pandarcap {
namespace {

constexpr std::uint16_t kEthertypeVlan = 0x8100;  // 802.1Q

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

// "ip and udp dst port N" as a classic BPF program for Ethernet frames, from libpcap's compiler.
struct CompiledFilter {
  bpf_program program{};
  ~CompiledFilter() { pcap_freecode(&program); }
};

void attach_port_filter(int fd, std::uint16_t port) {
  std::unique_ptr<pcap_t, decltype(&pcap_close)> dead(pcap_open_dead(DLT_EN10MB, 262144),
                                                      &pcap_close);
  if (!dead) throw std::runtime_error("pcap_open_dead failed");
  const std::string expression = fmt::format("ip and udp dst port {}", port);
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

// Whether a socket on this host holds UDP `port` on 0.0.0.0 (/proc/net/udp).
bool wildcard_holder(std::uint16_t port) {
  // Read as udp_port_owner reads it: bounded (one line of ~130 bytes a socket).
  const TextFile table = read_text_file("/proc/net/udp", 16u << 20);
  for (const UdpSocketEntry& entry : parse_proc_net_udp(table.text)) {
    if (entry.port == port && entry.address == 0) return true;
  }
  return false;
}

void attach_drop_all(int fd) {
  sock_filter drop{BPF_RET | BPF_K, 0, 0, 0};
  sock_fprog program{1, &drop};
  if (::setsockopt(fd, SOL_SOCKET, SO_ATTACH_FILTER, &program, sizeof program) != 0) {
    io::throw_errno("cannot attach a drop-all filter to the UDP socket on the data port");
  }
}

}  // namespace

PacketRingReceiver::PacketRingReceiver(const UdpReceiverOptions& options)
    : interface_(options.interface) {
  if (options.interface.empty()) {
    throw std::runtime_error(
        "input.receiver = \"packet_ring\" needs sensor.interface (--interface IFACE)");
  }
  ifindex_ = ::if_nametoindex(options.interface.c_str());
  if (ifindex_ == 0) {
    throw NoSuchInterface(fmt::format(
        "sensor.interface \"{}\": no such network interface here (`ip link` lists them)",
        options.interface));
  }
  if (!options.sensor_ip.empty()) {
    sources_ = SourceLock(ntohl(require_ipv4(options.sensor_ip, "sensor_ip").s_addr));
  }
  host_ip_ = ntohl(require_ipv4(options.host_ip, "host_ip").s_addr);
  if (host_ip_ == 0) {
    try {
      local_ = std::make_unique<LocalDestinations>();
    } catch (const std::exception& e) {
      // Not a reason to refuse the sensor: without the table, a datagram to another host that
      // reaches the interface with this one's MAC (routed through it) is taken too.
      spdlog::warn(
          "packet ring: {}: this host's addresses cannot be followed, so a datagram to any "
          "address that reaches {} with its MAC is taken (set sensor.host_ip to take one)",
          e.what(), options.interface);
    }
  }
  if (!options.multicast_ip.empty()) {
    multicast_ip_ = ntohl(require_ipv4(options.multicast_ip, "multicast_ip").s_addr);
  }
  open_guard(options);
  open_ring(options);
  empty_at_ns_ = monotonic_ns();  // the ring is new: nothing waits in it from before
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
    const int error = errno;
    // Another socket has the port. If it is bound to every address (0.0.0.0), it keeps the
    // host from answering already; bound to one address only, the others would answer with
    // ICMP: refused, as the socket receiver refuses a port in use.
    if (error == EADDRINUSE && options.port != 0 && wildcard_holder(options.port)) {
      spdlog::info(
          "UDP port {} is held on 0.0.0.0 by another socket, which keeps this host from "
          "answering the sensor's datagrams",
          options.port);
      port_ = options.port;
    } else {
      const std::string what = fmt::format(
          "cannot bind UDP {}:{} (the socket that keeps this host from answering the sensor's "
          "datagrams with ICMP)",
          options.host_ip, options.port);
      if (error == EADDRINUSE) {
        if (const std::string hint = port_in_use_hint(options.port); !hint.empty()) {
          throw std::runtime_error(fmt::format("{}: {}. {}", what, std::strerror(error), hint));
        }
      }
      io::throw_error(error, what);
    }
  } else {
    sockaddr_in bound{};
    socklen_t length = sizeof bound;
    if (::getsockname(guard_.get(), reinterpret_cast<sockaddr*>(&bound), &length) != 0) {
      io::throw_errno("getsockname");
    }
    port_ = ntohs(bound.sin_port);
  }
  // The group is joined on sensor.interface (or on multicast_interface_ip's), so the interface
  // takes the group's frames; a bound socket is not needed for the membership.
  if (!options.multicast_ip.empty()) {
    ip_mreqn membership{};
    membership.imr_multiaddr.s_addr = htonl(multicast_ip_);
    if (!options.multicast_interface_ip.empty()) {
      membership.imr_address =
          require_ipv4(options.multicast_interface_ip, "multicast_interface_ip");
    } else {
      membership.imr_ifindex = static_cast<int>(ifindex_);
    }
    if (::setsockopt(guard_.get(), IPPROTO_IP, IP_ADD_MEMBERSHIP, &membership, sizeof membership) !=
        0) {
      io::throw_errno(fmt::format("cannot join multicast group {} on {}", options.multicast_ip,
                                  options.interface));
    }
    spdlog::info("joined multicast group {} on {}", options.multicast_ip, options.interface);
  }
}

void PacketRingReceiver::open_ring(const UdpReceiverOptions& options) {
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

  const std::int64_t budget_ms = options.latency_budget_ns / 1'000'000;
  retire_ms_ = static_cast<std::uint32_t>(std::clamp<std::int64_t>(budget_ms, 1, kMaxRetireMs));
  if (options.receive_buffer_bytes > kMaxRingBytes) {
    spdlog::warn("packet ring: {} bytes asked for, {} MiB used (the most it takes)",
                 options.receive_buffer_bytes, kMaxRingBytes >> 20);
  }
  const std::uint64_t ring_bytes =
      std::clamp(options.receive_buffer_bytes, kMinRingBytes, kMaxRingBytes);
  // A full block is one wake's datagrams: no more than the pipeline takes at once.
  block_bytes_ = block_bytes_for(ring_bytes, options.expected_bytes_per_second, retire_ms_,
                                 options.max_wake_datagrams * options.expected_datagram_bytes);
  block_count_ = static_cast<std::uint32_t>(ring_bytes / block_bytes_);
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
  link.sll_ifindex = static_cast<int>(ifindex_);
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

std::uint32_t PacketRingReceiver::block_bytes_for(std::uint64_t ring_bytes,
                                                  std::uint64_t bytes_per_second,
                                                  std::uint32_t retire_ms,
                                                  std::uint64_t max_block_bytes) noexcept {
  ring_bytes = std::clamp(ring_bytes, kMinRingBytes, kMaxRingBytes);
  const std::uint64_t per_period = bytes_per_second * retire_ms / 1000;
  std::uint64_t largest =
      std::min<std::uint64_t>(kMaxBlockBytes, std::bit_floor(ring_bytes / kMinBlocks));
  if (max_block_bytes > 0) {
    largest =
        std::min(largest, std::max<std::uint64_t>(std::bit_floor(max_block_bytes), kMinBlockBytes));
  }
  return static_cast<std::uint32_t>(
      std::clamp<std::uint64_t>(std::bit_ceil(per_period), kMinBlockBytes, largest));
}

tpacket_block_desc* PacketRingReceiver::ready_block() noexcept {
  auto* block = reinterpret_cast<tpacket_block_desc*>(static_cast<std::uint8_t*>(map_) +
                                                      std::size_t{next_block_} * block_bytes_);
  // acquire: the packets the kernel wrote into the block happen before its status says so.
  const std::uint32_t status = __atomic_load_n(&block->hdr.bh1.block_status, __ATOMIC_ACQUIRE);
  return (status & TP_STATUS_USER) != 0 ? block : nullptr;
}

void PacketRingReceiver::take_block(tpacket_block_desc& block, PacketRing& ring,
                                    ReceiveCounters& counters) {
  const std::uint32_t count = block.hdr.bh1.num_pkts;
  const auto* base = reinterpret_cast<const std::uint8_t*>(&block);
  local_read_this_block_ = false;
  // Where the last turn stopped in this block, when the ring had no room for the rest.
  std::uint32_t offset = resume_index_ > 0 ? resume_offset_ : block.hdr.bh1.offset_to_first_pkt;
  std::uint64_t datagrams = 0, bytes = 0, truncated = 0, foreign = 0, other_sensor = 0;
  std::span<PacketSlot> slots;
  std::size_t filled = 0;
  std::size_t published = 0;
  bool whole = true;  // every frame of the block taken
  for (std::uint32_t i = resume_index_; i < count && offset != 0 && offset < block_bytes_; ++i) {
    const std::uint32_t frame_offset = offset;
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
    const std::optional<WireFrame> f = parse_wire_frame({mac, header->tp_snaplen}, header->tp_len);
    if (!f ||
        !for_this_host(f->destination_ip, link->sll_pkttype, link->sll_hatype == ARPHRD_LOOPBACK))
      continue;
    if (filled == slots.size()) {
      if (filled > 0) {
        ring.publish(filled);
        published += filled;
      }
      slots = ring.reserve(count - i);
      filled = 0;
    }
    if (slots.empty()) {
      // No room: the rest of the block stays in the kernel's ring for the next turn, after the
      // caller has emptied this one. A block is sized in bytes, so one of small datagrams can
      // hold more of them than the ring has slots; none is lost for that.
      whole = false;
      resume_index_ = i;
      resume_offset_ = frame_offset;
      break;
    }
    ++datagrams;
    bytes += f->arrived_bytes;
    PacketSlot& slot = slots[filled];
    slot.length = static_cast<std::uint32_t>(std::min(f->payload_bytes, sizeof slot.payload));
    // The frame's trailer (padding) is kept after the datagram where the slot has room, for the
    // recording; the decoder reads `length` bytes.
    slot.wire_trailer_length =
        static_cast<std::uint16_t>(std::min(f->trailer_bytes, sizeof slot.payload - slot.length));
    // Not copied: the decoder reads the datagram where the kernel wrote it, and the block goes
    // back only once every slot of it is taken (held_).
    slot.in_place = mac + f->header_bytes;
    slot.original_length = f->claimed_bytes;
    slot.truncated = f->truncated || slot.length < f->claimed_bytes;
    slot.receive_time_ns =
        std::int64_t{header->tp_sec} * 1'000'000'000 + std::int64_t{header->tp_nsec};
    slot.source.v4 = {};
    slot.source.v4.sin_family = AF_INET;
    slot.source.v4.sin_addr.s_addr = htonl(f->source_ip);
    slot.source.v4.sin_port = htons(f->source_port);
    slot.destination.v4 = {};
    slot.destination.v4.sin_family = AF_INET;
    slot.destination.v4.sin_addr.s_addr = htonl(f->destination_ip);
    slot.destination.v4.sin_port = htons(f->destination_port);
    // The headers as they were on the wire: the tag the kernel took out goes back after the
    // MAC addresses, with its own TPID (802.1Q unless the kernel says otherwise).
    const bool tagged = (header->tp_status & TP_STATUS_VLAN_VALID) != 0;
    const std::size_t wire_bytes = f->header_bytes + (tagged ? 4 : 0);
    slot.wire_length = static_cast<std::uint32_t>(header->tp_len + (tagged ? 4u : 0u));
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
      std::memcpy(out + at, mac + 12, f->header_bytes - 12);
      slot.wire_header_length = static_cast<std::uint8_t>(wire_bytes);
    } else {
      slot.wire_header_length = 0;  // recorded with synthesised headers
      slot.wire_trailer_length = 0;
    }
    truncated += slot.truncated;
    const SourceLock::Verdict verdict = sources_.judge(
        f->source_ip, f->source_port, std::span<const std::uint8_t>(slot.in_place, slot.length),
        slot.receive_time_ns);
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
  if (whole) {
    // Its datagrams are read in place by the decoder: it goes back to the kernel at the next
    // turn, when the ring is empty (give_back_held()).
    held_ = true;
    next_block_ = (next_block_ + 1) % block_count_;
    resume_index_ = 0;
    if (arrivals_seen_ > 0) --arrivals_seen_;  // counted from next_block_
  }

  ReceiveCounters::add(counters.datagrams, datagrams);
  ReceiveCounters::add(counters.bytes, bytes);
  ReceiveCounters::add(counters.truncated, truncated);
  ReceiveCounters::add(counters.foreign, foreign);
  ReceiveCounters::add(counters.other_sensor, other_sensor);
  counters.publish_sources(sources_.sensor_source(), sources_.other_source(),
                           sources_.source_changes());
  if (published > 0) ring.notify();
}

bool PacketRingReceiver::for_this_host(std::uint32_t destination, unsigned char packet_type,
                                       bool loopback) noexcept {
  // What a UDP socket bound to host_ip (and joined to multicast_ip) would be given: a datagram
  // to host_ip (any address of this host's, with 0.0.0.0), a broadcast, or the group.
  if (packet_type == PACKET_MULTICAST) return multicast_ip_ != 0 && destination == multicast_ip_;
  if (packet_type == PACKET_BROADCAST || destination == 0xFFFFFFFFu) return true;
  if (host_ip_ != 0) return destination == host_ip_;
  // 127.0.0.0/8 from the wire is a "martian" the kernel drops (unless route_localnet is set),
  // though the local table holds it.
  if ((destination >> 24) == 127 && !loopback) return false;
  if (local_ == nullptr || local_->contains(destination)) return true;
  // An address added since the last read (its change is queued before its first datagram can
  // arrive); once a block, so that traffic routed through the host costs no read a frame.
  if (local_read_this_block_) return false;
  local_read_this_block_ = true;
  local_->read_changes();
  return local_->contains(destination);
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

void PacketRingReceiver::take_socket_error(ReceiveCounters& counters) noexcept {
  int error = 0;
  socklen_t length = sizeof error;
  if (::getsockopt(fd_.get(), SOL_SOCKET, SO_ERROR, &error, &length) != 0 || error == 0) return;
  ReceiveCounters::add(counters.receive_errors, 1);
  if (!link_down_) {
    spdlog::warn("packet ring: {}: {}: nothing arrives until it is up again", interface_,
                 std::strerror(error));
  }
  link_down_ = true;
  link_down_at_ns_ = realtime_ns();
  next_link_check_ns_ = 0;
}

void PacketRingReceiver::look_for_interface(std::int64_t now_ns) noexcept {
  if (now_ns < next_link_check_ns_) return;
  next_link_check_ns_ = now_ns + 1'000'000'000;
  // The same interface up again delivers by itself; one removed and made again has a new
  // index, which the socket must be bound to.
  const unsigned index = ::if_nametoindex(interface_.c_str());
  if (index == 0 || index == ifindex_) return;
  sockaddr_ll link{};
  link.sll_family = AF_PACKET;
  link.sll_protocol = htons(ETH_P_ALL);
  link.sll_ifindex = static_cast<int>(index);
  if (::bind(fd_.get(), reinterpret_cast<const sockaddr*>(&link), sizeof link) == 0) {
    ifindex_ = index;
    spdlog::info("packet ring: {} is back (index {}): bound to it again", interface_, index);
  }
}

ReceiveTurn PacketRingReceiver::receive(PacketRing& ring, const std::atomic<bool>& stop,
                                        ReceiveCounters& counters,
                                        std::atomic<std::uint64_t>& heartbeat) {
  // On stop the block being filled is handed over by its retire timer at the latest: waiting
  // for that (twice its period) takes every frame the kernel accepted before the stop.
  const std::int64_t drain_ns = std::max<std::int64_t>(200'000'000, 3'000'000LL * retire_ms_);
  const std::int64_t now = coarse_monotonic_ns();
  if (drain_until_ == 0 && stop.load(std::memory_order_relaxed)) {
    counters.note_stop(now);
    drain_until_ = now + drain_ns;
  }
  const bool draining = drain_until_ != 0;
  // The last block's datagrams were read in place; the caller has emptied the ring since (it
  // turns only then), so nothing reads the block any more. A caller that turns early is told
  // to take what the ring holds first.
  if (held_) {
    if (ring.size_approx() != 0) return ReceiveTurn::kTook;
    give_back_held();
  }
  if (draining && now >= drain_until_) return ReceiveTurn::kEnded;
  ReceiveCounters::add(heartbeat, 1);
  note_arrivals(counters);
  if (now >= next_statistics_ns_) {
    read_statistics(counters);
    if (local_ != nullptr) local_->refresh();  // what the changes could not say, set right
    next_statistics_ns_ = now + 1'000'000'000;
  }
  if (tpacket_block_desc* block = ready_block()) {
    // A block the retire timer hands over after the error may hold only frames from before it:
    // the interface delivers again when a frame arrived after the error.
    const tpacket_bd_ts& last = block->hdr.bh1.ts_last_pkt;
    if (link_down_ && std::int64_t{last.ts_sec} * 1'000'000'000 + last.ts_nsec > link_down_at_ns_) {
      link_down_ = false;
      spdlog::info("packet ring: {} delivers again", interface_);
    }
    take_block(*block, ring, counters);
    return ReceiveTurn::kTook;
  }
  if (link_down_) look_for_interface(now);
  // No block ready: sleep until the kernel hands one over (full, or its timer ran out).
  pollfd pfd{fd_.get(), POLLIN | POLLERR, 0};
  const int timeout_ms = draining ? static_cast<int>(2 * retire_ms_ + 1) : 100;
  const int ready = ::poll(&pfd, 1, timeout_ms);
  ReceiveCounters::add(counters.wakeups, 1);
  if (ready < 0 && errno != EINTR) ReceiveCounters::add(counters.receive_errors, 1);
  // The interface went down or away: the error stays set (and poll() returns at once) until
  // it is read.
  if (ready > 0 && (pfd.revents & POLLERR) != 0) take_socket_error(counters);
  // Nothing more is coming.
  if (ready == 0 && draining && ready_block() == nullptr) return ReceiveTurn::kEnded;
  return ReceiveTurn::kWaited;
}

void PacketRingReceiver::give_back_held() noexcept {
  auto* block = reinterpret_cast<tpacket_block_desc*>(
      static_cast<std::uint8_t*>(map_) +
      std::size_t{(next_block_ + block_count_ - 1) % block_count_} * block_bytes_);
  // release: the kernel may write the block again once every read of it is done.
  __atomic_store_n(&block->hdr.bh1.block_status, TP_STATUS_KERNEL, __ATOMIC_RELEASE);
  held_ = false;
}

std::uint32_t PacketRingReceiver::blocks_ahead() const noexcept {
  return block_count_ - (held_ ? 1u : 0u);
}

std::uint64_t PacketRingReceiver::frames_unread() const noexcept {
  std::uint64_t unread = 0;
  for (std::uint32_t n = 0; n < blocks_ahead(); ++n) {
    const std::uint32_t index = (next_block_ + n) % block_count_;
    const auto* block = reinterpret_cast<const tpacket_block_desc*>(
        static_cast<const std::uint8_t*>(map_) + std::size_t{index} * block_bytes_);
    if ((__atomic_load_n(&block->hdr.bh1.block_status, __ATOMIC_ACQUIRE) & TP_STATUS_USER) == 0)
      break;
    const std::uint32_t taken = n == 0 ? resume_index_ : 0;
    unread += block->hdr.bh1.num_pkts > taken ? block->hdr.bh1.num_pkts - taken : 0;
  }
  return unread;
}

std::uint32_t PacketRingReceiver::blocks_waiting() const noexcept {
  std::uint32_t n = 0;
  for (; n < blocks_ahead(); ++n) {
    const std::uint32_t index = (next_block_ + n) % block_count_;
    const auto* block = reinterpret_cast<const tpacket_block_desc*>(
        static_cast<const std::uint8_t*>(map_) + std::size_t{index} * block_bytes_);
    if ((__atomic_load_n(&block->hdr.bh1.block_status, __ATOMIC_ACQUIRE) & TP_STATUS_USER) == 0)
      break;
  }
  return n + (held_ ? 1u : 0u);
}

void PacketRingReceiver::finish(ReceiveCounters& counters) noexcept {
  // A backlog longer than the stop's drain: the blocks it did not reach are counted as dropped
  // (the kernel's count is of the frames its filter passed, as these are), not left in no
  // counter.
  if (const std::uint64_t unread = frames_unread(); unread > 0) {
    kernel_drops_ += unread;
    spdlog::warn(
        "packet ring: the stop's drain ended with {} frames still in the ring (a backlog longer "
        "than it takes): counted as kernel drops",
        unread);
  }
  read_statistics(counters);  // the last drops, for the final health
  if (queue_freezes_ > 0) {
    spdlog::warn("packet ring: the kernel found no free block {} times ({} frames dropped)",
                 queue_freezes_, kernel_drops_);
  }
}

}  // namespace pandarcap
