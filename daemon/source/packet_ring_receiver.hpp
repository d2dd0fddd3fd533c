// The AF_PACKET receiver (input.receiver = "packet_ring"): the kernel writes every frame that
// passes a BPF filter into a TPACKET_V3 ring of blocks mapped into this process, and hands over a
// whole block at a time; the blocks are read in place, with no system call per packet or per
// batch (only a poll() when no block is ready). tcpdump reads the same way, which is why it
// records for less than any recvmmsg loop.
//
// The kernel's ring is the queue between receive and decode: the decode thread reads it itself,
// a block at a time between its batches (receive()), and no thread of ours sits between the two.
// A thread that only moved blocks on cost as much as the decoding (0.4-0.5 % of a core at one
// sensor's rate, against the decoder's 0.6: 200 wake-ups a second each, and a futex wake of the
// decoder per block); read by the decoder, the daemon measured a median 1.70 % of a core where
// it had measured 1.98 % (alternated bench runs; docs/performance.md, "Fourth round").
//
// The socket and filter: SOCK_RAW on sensor.interface, with a classic BPF program for UDP to the
// data port compiled by libpcap (pcap_compile; "udp dst port N"). It is attached before the
// socket is bound, so no other frame ever enters the ring. sensor_ip is judged after the filter,
// as the socket receiver judges it (core/decode/source_lock.hpp): a second sensor on the port is
// still seen, counted and named, not filtered out unseen. Frames this host sent (loopback's
// second copy) or that were meant for another host (a promiscuous interface) are skipped, as the
// kernel's UDP socket would never have received them.
//
// The ring: udp_socket_receive_buffer_size_bytes of 32 KiB blocks (32 to 32768: 1 MiB to 1 GiB,
// all of it locked kernel memory). The kernel hands a block over when it is full or when its
// retire timer runs out: the timer is the latency budget (latency.budget_ms, 1 to 100 ms: the
// kernel's unit, and a stop waits for it), so a packet waits in the ring no longer than that.
//
// Only what a UDP socket on host_ip would have been given is taken: IPv4 (the filter is
// "ip and udp dst port N"), to host_ip (any address with 0.0.0.0), a broadcast, or
// multicast_ip. The lengths are the frame's, checked against each other (core/wire_frame.hpp):
// a datagram the frame does not hold whole (a first fragment, a UDP length past the packet) is
// counted as truncated, and the decoder rejects it.
//
// The interface going down or away: the socket's error (POLLERR) is read and counted as a
// receive error, logged with the interface's name; the thread sleeps in poll() meanwhile, and
// binds again when an interface of that name is back. It delivers again when a block holds a
// frame that arrived after the error (a block the retire timer hands over after the down holds
// only frames from before it).
//
// Each packet keeps its kernel timestamp (tp_sec/tp_nsec, nanoseconds) and its headers as the
// wire carried them, the VLAN tag put back from tp_vlan_tci (with its TPID), so the pcap holds
// the frame byte for byte as `tcpdump -w` writes it (PacketSlot::wire_header).
//
// Each datagram gets a PacketRing slot with its times, addresses and headers, but its bytes stay
// where the kernel wrote them (PacketSlot::in_place): the decoder and the recording read them in
// the block, so the accounting and the decoder are the socket receiver's and no datagram is
// copied before it is decoded. (Less work, not a measured saving: the first read of a line the
// kernel wrote still pays for fetching it, now in the recording's copy; docs/performance.md,
// tenth round.) A block taken whole is held until the next turn, when the decoder has emptied
// the ring; then it goes back to the kernel. So one block at most is ours and not the kernel's:
// the ring's depth is its block count less one.
//
// Drops: PACKET_STATISTICS (tp_drops, the frames the kernel had no free block for) is read once a
// second and at the end; reading resets it, so it is added up into kernel_drops. A block is
// sized in bytes, so one of small datagrams may hold more than the PacketRing has slots: what does
// not fit stays in the block, which the next turn goes on reading once the decoder has emptied
// the ring. Nothing is dropped between the two rings (no ring overruns), and a backlog waits in
// the kernel's, where its drops are counted. A stop drains the ring for 200 ms at least (the open
// block's retire timer); what a longer backlog leaves in it is counted as kernel drops too.
//
// No reply from this host: without a UDP socket on the data port the kernel answers every
// datagram with ICMP port-unreachable (a flood towards the sensor). A UDP socket is bound to
// host_ip:data_port with a BPF program that drops everything, so it costs nothing; it also joins
// multicast_ip when one is set, so the interface takes the group's frames.
//
// Privilege: AF_PACKET needs CAP_NET_RAW. Without it the error names the capability and the
// systemd drop-in that grants it (systemd/pandarcapd-packet-ring.conf; docs/deploy.md).
#pragma once

#include <linux/if_packet.h>

#include <atomic>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>

#include "core/decode/source_lock.hpp"
#include "daemon/io/unique_fd.hpp"
#include "daemon/packet_slot.hpp"
#include "daemon/pipeline_types.hpp"
#include "daemon/source/local_destinations.hpp"
#include "daemon/source/udp_receiver.hpp"

namespace pandarcap {

// The start-up errors a caller tells apart (exit 77 and 78): no CAP_NET_RAW, and an interface
// this host does not have.
struct MissingCapability : std::runtime_error {
  using std::runtime_error::runtime_error;
};
struct NoSuchInterface : std::runtime_error {
  using std::runtime_error::runtime_error;
};

class PacketRingReceiver {
 public:
  // Blocks sized to what the sensor sends in one retire period (18 packets of a 40P in the
  // default 5 ms: 32 KiB; 100 ms without frames: 512 KiB). At the sensor's rate the timer, not
  // the size, then sets the wake-ups (one per period), and the ring's depth in time is what its
  // bytes hold at that rate, less what the timer leaves empty in each block (8 MiB: 1.3 s at
  // 5 ms, 1.6 s at 100 ms). A slower stream fills blocks less: its depth is the block count
  // times the period. A jumbo frame (9 kB) fits any block. Blocks are no larger than one wake
  // should hand on (UdpReceiverOptions::max_wake_datagrams).
  static constexpr std::uint32_t kMinBlockBytes = 32 * 1024;
  static constexpr std::uint32_t kMaxBlockBytes = 4 * 1024 * 1024;
  static constexpr std::uint32_t kMinBlocks = 16;           // a block is the unit of loss
  static constexpr std::uint64_t kMinRingBytes = 1u << 20;  // 1 MiB
  static constexpr std::uint64_t kMaxRingBytes = 1u << 30;  // 1 GiB
  static constexpr std::int64_t kMaxRetireMs = 100;         // a stop waits up to 3 of these
  static constexpr std::uint32_t kFrameBytes = 2048;        // the kernel's bookkeeping unit

  // Opens the guard socket, the packet socket and its ring on options.interface. Throws
  // std::runtime_error naming the step (and the capability, when it is missing).
  explicit PacketRingReceiver(const UdpReceiverOptions& options);
  ~PacketRingReceiver();
  PacketRingReceiver(const PacketRingReceiver&) = delete;
  PacketRingReceiver& operator=(const PacketRingReceiver&) = delete;

  // The block size for a ring of `ring_bytes` (clamped to 1 MiB..1 GiB) whose blocks retire
  // after `retire_ms`, for a sensor sending `bytes_per_second` (see kMinBlockBytes), and no
  // larger than `max_block_bytes` (0: no bound) unless that is below kMinBlockBytes.
  static std::uint32_t block_bytes_for(std::uint64_t ring_bytes, std::uint64_t bytes_per_second,
                                       std::uint32_t retire_ms,
                                       std::uint64_t max_block_bytes = 0) noexcept;

  // The data port filtered for (the guard socket's: port 0 asks the kernel for a free one).
  std::uint16_t bound_port() const noexcept { return port_; }
  std::uint64_t ring_bytes() const noexcept { return std::uint64_t{block_bytes_} * block_count_; }

  // One turn of the receive loop, on the thread that reads the ring between its other work
  // (the decoder's: daemon/source/packet_source.hpp): takes the next block the kernel handed
  // over into `ring`, or waits up to 100 ms for one. One block at most, and no more of it than
  // `ring` has room for (the rest on the next turn), so the caller empties `ring` between turns
  // and a backlog waits in the kernel's ring, not in `ring`. Says which it did; kEnded once `stop`
  // was set and every block before it taken (the block being filled is handed over by its retire
  // timer within 3 periods), and then call finish(). `heartbeat` counts the turns, for the
  // watchdog. Called only by the thread that consumes `ring` too (the decode thread): a turn
  // gives the block it read in place back to the kernel, so `ring` must be empty then, and
  // only that thread can know it is (a turn with `ring` not empty takes nothing: kTook).
  ReceiveTurn receive(PacketRing& ring, const std::atomic<bool>& stop, ReceiveCounters& counters,
                      std::atomic<std::uint64_t>& heartbeat);
  // After the last receive(): the last drops read into the counters, with the frames a stop's
  // drain left in the ring (a backlog longer than the drain).
  void finish(ReceiveCounters& counters) noexcept;
  // The blocks the kernel cannot fill: handed over and not taken (a block taken in part counts),
  // and the one held while the decoder reads it in place. While fewer than half, the reader may
  // wait for its own consumer (the writer) and leave the backlog here (DecodeWorker); it grows
  // while packets arrive.
  std::uint32_t blocks_waiting() const noexcept;
  std::uint32_t block_count() const noexcept { return block_count_; }
  // Notes in `counters` when the sensor's newest packet of the blocks handed over since the
  // last call arrived (the health's last packet; receive() calls it each turn, and a reader that
  // waits for its consumer meanwhile should too), how far that is complete (seen_until: not
  // while every block is handed over, when the kernel drops what arrives).
  void note_arrivals(ReceiveCounters& counters) noexcept;

 private:
  void open_guard(const UdpReceiverOptions& options);
  void open_ring(const UdpReceiverOptions& options);
  // The block the kernel handed over (TP_STATUS_USER), or null.
  tpacket_block_desc* ready_block() noexcept;
  // Puts a block's datagrams into the ring (their bytes left in the block) and holds the block
  // until the next turn; or, when the ring has no room for the rest, keeps it and where it
  // stopped for the next turn.
  void take_block(tpacket_block_desc& block, PacketRing& ring, ReceiveCounters& counters);
  // The held block (the one before next_block_) back to the kernel.
  void give_back_held() noexcept;
  // The blocks from next_block_ that can be the kernel's or handed over: all but the held one.
  std::uint32_t blocks_ahead() const noexcept;
  // The frames in the blocks the kernel has handed over and this side has not taken.
  std::uint64_t frames_unread() const noexcept;
  // Adds the kernel's drops since the last read to kernel_drops.
  void read_statistics(ReceiveCounters& counters) noexcept;
  // When the newest of a handed-over block's datagrams from the sensor (sources_, as it stands)
  // arrived (CLOCK_REALTIME ns), or 0: none. Other hosts' datagrams on the port say nothing of
  // the sensor.
  std::int64_t newest_sensor_arrival(const tpacket_block_desc& block) const noexcept;
  // Whether a UDP socket on host_ip (joined to multicast_ip) would have been given a datagram
  // to `destination` (host order) arriving as `packet_type` (PACKET_HOST, ...) on a loopback
  // interface or not. With 0.0.0.0:
  // a destination the kernel delivers here (local_); one not known reads the changes queued
  // since, once a block.
  bool for_this_host(std::uint32_t destination, unsigned char packet_type, bool loopback) noexcept;
  // The socket's pending error (POLLERR: the interface went down or away), read and cleared.
  void take_socket_error(ReceiveCounters& counters) noexcept;
  // While the interface is away: binds again once it is back (a new interface of the same
  // name has a new index).
  void look_for_interface(std::int64_t now_ns) noexcept;

  io::UniqueFd guard_;  // the drop-all UDP socket on the data port
  io::UniqueFd fd_;     // the packet socket
  void* map_ = nullptr;
  std::uint32_t block_bytes_ = kMinBlockBytes;
  std::uint32_t block_count_ = 0;
  std::uint32_t next_block_ = 0;
  std::uint32_t resume_index_ = 0;   // the next frame of next_block_ to take (0: a new block)
  std::uint32_t resume_offset_ = 0;  // its offset in the block
  std::uint32_t arrivals_seen_ = 0;  // blocks from next_block_ whose arrival is noted
  bool held_ = false;  // the block before next_block_ is taken whole, its datagrams maybe unread
  std::int64_t empty_at_ns_ = 0;        // CLOCK_MONOTONIC: when no block waited at a look
  std::int64_t next_drop_read_ns_ = 0;  // note_arrivals reads the drops again from then
  std::uint64_t drops_noted_ = 0;       // kernel_drops_ when their arrival was last noted
  std::uint32_t retire_ms_ = 1;
  std::uint16_t port_ = 0;
  std::string interface_;
  unsigned ifindex_ = 0;
  std::uint32_t host_ip_ = 0;  // host order; 0 = any address of this host
  // host_ip 0.0.0.0: the destinations the kernel delivers here (null: any; see the start's log).
  std::unique_ptr<LocalDestinations> local_;
  bool local_read_this_block_ = false;
  std::uint32_t multicast_ip_ = 0;    // host order; 0 = none
  bool link_down_ = false;            // an error said so; until a frame arrives after it
  std::int64_t link_down_at_ns_ = 0;  // when the error was read (CLOCK_REALTIME, as the frames')
  std::int64_t next_link_check_ns_ = 0;
  std::int64_t next_statistics_ns_ = 0;
  std::int64_t drain_until_ = 0;  // when a stop's drain ends (0: no stop yet)
  std::uint64_t kernel_drops_ = 0;
  std::uint64_t queue_freezes_ = 0;
  SourceLock sources_{std::nullopt};
};

}  // namespace pandarcap
