// The receive thread's socket and loop: datagrams go from the kernel straight into PacketRing
// slots with recvmmsg (zero copy), a batch per system call.
//
// Socket: IPv4 UDP bound to host_ip:data_port, optional multicast join, SO_RCVBUF as requested
// (SO_RCVBUFFORCE first when permitted; the granted size is logged, with the sysctl to raise
// when net.core.rmem_max capped it), SO_TIMESTAMPNS for kernel receive times, and a 100 ms
// receive timeout so the per-datagram loop notices shutdown.
//
// A batch: reserve up to `batch` free slots, recvmmsg(MSG_TRUNC) into them, then per datagram:
// record a cut one as truncated with its real length, take the kernel time, and drop (count) a
// datagram that is not the sensor's (core/decode/source_lock.hpp: sensor_ip, or the first source
// when none is set; a valid packet from elsewhere is another sensor, counted and named in the
// health). Publish the rest with one store. Ring full: receive
// the waiting datagrams into a scratch buffer and count them as overruns (drop newest) — never
// block on the decoder. No allocation, no locks in the loop.
//
// Waiting, by the latency budget:
//   budget 0   recvmmsg(MSG_WAITFORONE) blocks until a datagram: the thread wakes, and wakes the
//              decoder, for (nearly) every datagram at one sensor's rate. Kernel drops are read
//              once a second with SO_MEMINFO.
//   budget > 0 the thread sleeps on an absolute CLOCK_MONOTONIC deadline, then drains the socket
//              with recvmmsg(MSG_DONTWAIT) in full batches until one comes back short, and
//              notifies the decoder once. The socket buffer holds what arrives meanwhile (8 MiB
//              is ~1.7 s of one sensor). At each wake SO_MEMINFO says how full the buffer got;
//              the next sleep is shortened so that, at that rate, it would be at most 1/8 full
//              at the next wake, and grows back (x2 per wake) up to the budget. Kernel receive
//              timestamps keep every datagram's true arrival time.
#pragma once

#include <netinet/in.h>

#include <atomic>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "core/decode/source_lock.hpp"
#include "daemon/packet_slot.hpp"
#include "daemon/pipeline_types.hpp"

namespace pandarcap {

struct UdpReceiverOptions {
  std::string host_ip = "0.0.0.0";
  std::uint16_t port = 2368;  // 0 = any free port (the simulator uses it)
  std::string multicast_ip;
  std::string multicast_interface_ip;
  std::uint64_t receive_buffer_bytes = 8u << 20;
  std::string sensor_ip;  // "" = the first source that sends a packet (core/decode/source_lock.hpp)
  std::size_t batch = 64;
  std::int64_t latency_budget_ns = 0;  // 0: wake per datagram; see above
  // input.receiver = "packet_ring": an AF_PACKET ring on `interface` instead of this socket
  // (daemon/source/packet_ring_receiver.hpp), with the same options otherwise.
  bool packet_ring = false;
  std::string interface;
  // What the sensor sends at most, for the packet ring's block size: a Pandar40P in dual return.
  std::uint64_t expected_bytes_per_second = 3600 * 1266;
  std::uint64_t expected_datagram_bytes = 1266 + 42;  // with its Ethernet, IP and UDP headers
  // The most datagrams one wake should hand on (0: no bound): everything a wake takes reaches
  // the decoder, and its raw batches, at once, so a faster stream makes the sleeps shorter (the
  // socket receiver) or the blocks smaller (the packet ring) rather than overrun them.
  std::size_t max_wake_datagrams = 0;
};

class UdpReceiver {
 public:
  // Opens and configures the socket. Throws std::system_error naming the step that failed.
  explicit UdpReceiver(const UdpReceiverOptions& options);
  ~UdpReceiver();
  UdpReceiver(const UdpReceiver&) = delete;
  UdpReceiver& operator=(const UdpReceiver&) = delete;

  std::uint16_t bound_port() const noexcept { return ntohs(bound_.sin_port); }
  std::uint64_t granted_receive_buffer_bytes() const noexcept { return granted_rcvbuf_; }

  // Receives until `stop` is set (checked at least every 100 ms).
  void run(PacketRing& ring, const std::atomic<bool>& stop, ReceiveCounters& counters,
           std::atomic<std::uint64_t>& heartbeat);

 private:
  struct Batch;
  // One recvmmsg into free ring slots (or the scratch slots when the ring is full).
  struct Received {
    std::size_t received = 0;   // datagrams the kernel gave (0: none waiting, or the timeout)
    std::size_t requested = 0;  // slots offered: received < requested means the socket is empty
    bool overrun = false;       // the ring was full: received into scratch, dropped and counted
    std::size_t published = 0;  // datagrams published to the ring
  };
  // Below 1/8 full at each wake: a burst at several times the rate of the last sleep still fits.
  static constexpr double kTargetFill = 0.125;
  static constexpr std::int64_t kMinSleepNs = 100'000;

  void configure(const UdpReceiverOptions& options);
  // Reads SO_MEMINFO: stores the kernel's drop count (plus left_at_stop_), notes an arrival now
  // when it grew (what was dropped came after what the buffer held), returns the buffer's fill
  // (0..1).
  double read_socket_memory(ReceiveCounters& counters);
  // The longest a running receiver goes between receives: SO_RCVTIMEO's 100 ms, or a coalesced
  // sleep (the latency budget at most).
  std::int64_t look_interval_ns() const noexcept {
    return budget_ns_ == 0 ? 100'000'000 : budget_ns_;
  }
  // After the stop's drain: receives, without keeping them, the datagrams the socket still holds
  // that arrived before this call, and adds them to left_at_stop_ (counted as kernel drops: the
  // socket's close would drop them). Returns how many.
  std::uint64_t count_left_at_stop();
  Received receive_batch(PacketRing& ring, int flags, ReceiveCounters& counters);
  void run_per_datagram(PacketRing& ring, const std::atomic<bool>& stop, ReceiveCounters& counters,
                        std::atomic<std::uint64_t>& heartbeat);
  void run_coalesced(PacketRing& ring, const std::atomic<bool>& stop, ReceiveCounters& counters,
                     std::atomic<std::uint64_t>& heartbeat);

  int fd_ = -1;
  sockaddr_in bound_{};  // host_ip:port as bound
  std::uint64_t granted_rcvbuf_ = 0;
  SourceLock sources_{std::nullopt};
  std::size_t batch_;
  std::int64_t budget_ns_ = 0;
  std::size_t max_wake_datagrams_ = 0;
  std::uint64_t left_at_stop_ = 0;
  std::int64_t empty_at_ns_ = 0;     // CLOCK_MONOTONIC: when a receive last found the socket empty
  std::uint32_t meminfo_drops_ = 0;  // SO_MEMINFO's drop count at the last read
  std::int64_t next_drop_look_ns_ = 0;  // a drained socket's drops are read again from then
  std::unique_ptr<Batch> buffers_;
};

}  // namespace pandarcap
