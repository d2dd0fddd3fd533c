// The receive thread's socket and loop: datagrams go from the kernel straight into PacketRing
// slots with recvmmsg (zero copy), a batch per system call.
//
// Socket: IPv4 UDP bound to host_ip:data_port, optional multicast join, SO_RCVBUF as requested
// (SO_RCVBUFFORCE first when permitted; the granted size is logged, with the sysctl to raise
// when net.core.rmem_max capped it), SO_TIMESTAMPNS for kernel receive times, SO_RXQ_OVFL, and
// a 100 ms receive timeout so the loop notices shutdown.
//
// Loop: reserve up to `batch` free slots, recvmmsg(MSG_WAITFORONE) into them, then per datagram:
// record MSG_TRUNC as truncated, take the kernel time, and drop (count) a datagram whose source
// is not sensor_ip. Publish the rest with one store and notify the decoder once per batch.
// Ring full: receive the waiting datagrams into a scratch buffer and count them as overruns
// (drop newest) — never block on the decoder. Kernel drops are read once a second with
// SO_MEMINFO. No allocation, no locks in the loop.
#pragma once

#include <netinet/in.h>

#include <atomic>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "daemon/pipeline_types.hpp"
#include "ringbuf/packet_slot.hpp"

namespace pandarcap {

struct UdpReceiverOptions {
  std::string host_ip = "0.0.0.0";
  std::uint16_t port = 2368;  // 0 = any free port (the simulator uses it)
  std::string multicast_ip;
  std::string multicast_interface_ip;
  std::uint64_t receive_buffer_bytes = 8u << 20;
  std::string sensor_ip;  // "" = accept every source
  std::size_t batch = 64;
};

class UdpReceiver {
 public:
  // Opens and configures the socket. Throws std::system_error naming the step that failed.
  explicit UdpReceiver(const UdpReceiverOptions& options);
  ~UdpReceiver();
  UdpReceiver(const UdpReceiver&) = delete;
  UdpReceiver& operator=(const UdpReceiver&) = delete;

  std::uint16_t bound_port() const noexcept { return bound_port_; }
  std::uint64_t granted_receive_buffer_bytes() const noexcept { return granted_rcvbuf_; }

  // Receives until `stop` is set (checked at least every 100 ms).
  void run(ringbuf::PacketRing& ring, const std::atomic<bool>& stop, ReceiveCounters& counters,
           std::atomic<std::uint64_t>& heartbeat);

 private:
  struct Batch;
  void configure(const UdpReceiverOptions& options);
  void read_kernel_drops(ReceiveCounters& counters);

  int fd_ = -1;
  std::uint16_t bound_port_ = 0;
  std::uint64_t granted_rcvbuf_ = 0;
  std::optional<in_addr_t> sensor_ip_;  // network order
  std::size_t batch_;
  std::unique_ptr<Batch> buffers_;
};

}  // namespace pandarcap
