// PacketSlot and PacketRing: what the receive thread hands the decoder.
//
// A slot holds one UDP datagram exactly as recvmmsg wrote it, with what the kernel said about it.
// The payload buffer is sized for the largest datagram the decoder accepts (1266 bytes: a
// Pandar40P packet with its 4-byte UDP sequence) plus slack to a whole number of cache lines; a
// larger datagram is cut by the kernel and marked `truncated` (MSG_TRUNC), and the decoder rejects
// it by length and counts it. Slots are 64-byte aligned so one slot's header never shares a cache
// line with the previous slot's payload.
#pragma once

#include <netinet/in.h>

#include <cstddef>
#include <cstdint>

#include "core/sensors/sensor_models.hpp"
#include "daemon/pcap/endpoint.hpp"
#include "ringbuf/slot_ring.hpp"

namespace pandarcap {

// A datagram's address as the socket API holds it: IPv4 from the live socket (the daemon binds
// an IPv4 socket; the sensor speaks IPv4), IPv4 or IPv6 from a replayed capture. The family
// field, first in both (their common initial sequence), says which.
union SlotAddress {
  sockaddr_in v4;
  sockaddr_in6 v6;
};

inline SlotAddress to_slot_address(const Endpoint& endpoint) noexcept {
  SlotAddress address{};
  if (endpoint.ipv6) {
    address.v6 = to_sockaddr6(endpoint);
  } else {
    address.v4 = to_sockaddr(endpoint);
  }
  return address;
}

inline Endpoint to_endpoint(const SlotAddress& address) noexcept {
  return address.v4.sin_family == AF_INET6 ? to_endpoint(address.v6) : to_endpoint(address.v4);
}

// Largest datagram the decoder accepts: the largest of any supported model, the Pandar40P's
// (spec §1: 1262 bytes, or 1266 with the UDP sequence; core/sensors/sensor_models.hpp).
inline constexpr std::size_t kMaxAcceptedDatagram = kLargestDatagramBytes;

// Room for a frame's headers: Ethernet (14), two VLAN tags (8), IPv4 with options (up to 60) and
// UDP (8) = 90. A frame with more is recorded with synthesised headers instead.
inline constexpr std::size_t kWireHeaderCapacity = 96;

struct alignas(ringbuf::kCacheLine) PacketSlot {
  // Room for the largest accepted datagram, rounded up so the slot is whole cache lines.
  static constexpr std::size_t kPayloadCapacity = 1280;
  static_assert(kPayloadCapacity >= kMaxAcceptedDatagram);

  std::uint8_t payload[kPayloadCapacity];
  // Where the datagram's bytes are: null when they are in `payload` (the socket receiver, a
  // replay); otherwise in the packet ring's block the kernel wrote them into, which is given back
  // only once the decoder has taken every slot of it (daemon/source/packet_ring_receiver.hpp), so
  // the packet ring's datagrams are never copied before they are decoded.
  const std::uint8_t* in_place = nullptr;
  // Bytes kept (at most kPayloadCapacity).
  std::uint32_t length;
  // Bytes the datagram had (MSG_TRUNC's real length; a capture record's UDP length): equal to
  // `length` unless the datagram was cut. The recording writes it as the record's original length.
  std::uint32_t original_length;
  // The datagram was longer than what was kept (MSG_TRUNC on the live path; a record a capture
  // file holds only part of, on replay): the decoder rejects it as bad_length.
  bool truncated;
  // Kernel receive time (SO_TIMESTAMPNS, CLOCK_REALTIME ns), or the time recvmmsg returned when
  // the kernel gave none; 0 for replayed packets that had no capture time.
  std::int64_t receive_time_ns;
  // Sender, as recvmmsg wrote it (IPv4), or a replayed record's (IPv4 or IPv6).
  SlotAddress source;
  // The frame's own headers as the wire carried them (Ethernet, the VLAN tag put back, IPv4,
  // UDP), for the recording: kept by the packet_ring receiver, which sees whole frames, so its
  // pcap holds what `tcpdump -w` would. 0 bytes from the socket receiver and a replay: their
  // recordings synthesise the headers (daemon/pcap/pcap_writer.hpp).
  std::uint8_t wire_header_length;
  std::uint8_t wire_header[kWireHeaderCapacity];
  // With wire_header: the frame's bytes after the datagram, kept in `payload` after `length`
  // (Ethernet padding of a short frame, or what a UDP length field left out), and the frame's
  // length on the wire (the tag included), which is the record's original length.
  std::uint16_t wire_trailer_length;
  std::uint32_t wire_length;
  // Where the datagram was sent: the address in its IP header (IP_PKTINFO: a unicast, broadcast
  // or multicast address) and the port the socket is bound to; a replay's record's own. The
  // recording writes it as the packet's destination, as the wire carried it.
  SlotAddress destination;

  // The datagram's bytes (`length` of them, then `wire_trailer_length` of the frame's trailer).
  const std::uint8_t* data() const noexcept { return in_place != nullptr ? in_place : payload; }
};

static_assert(sizeof(PacketSlot) % ringbuf::kCacheLine == 0);

using PacketRing = ringbuf::SlotRing<PacketSlot>;

}  // namespace pandarcap
