// An Ethernet frame carrying an IPv4 UDP datagram, as a packet socket hands it over: where the
// datagram is, how long it says it is, and what else the frame holds. For the packet_ring
// receiver (daemon/source/packet_ring_receiver.hpp), which reads frames the kernel's UDP has not
// checked: every length is taken from the frame and held against the bytes that are there.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>

namespace pandarcap {

struct WireFrame {
  std::size_t header_bytes = 0;     // Ethernet (+ in-band tags), IPv4 (+ options), UDP
  std::size_t payload_bytes = 0;    // the datagram's bytes held: its UDP length or what is there
  std::size_t trailer_bytes = 0;    // held after the datagram (Ethernet padding, or a UDP length
                                    // that says less than the IP packet holds)
  std::uint32_t claimed_bytes = 0;  // the datagram's length by its UDP header
  std::uint32_t arrived_bytes = 0;  // of those, how many the frame on the wire held
  // The datagram is not whole here: cut by the capture, a first fragment, or lengths that
  // contradict each other (a UDP length under 8 or past the IP packet, an IP length past the
  // frame). The kernel's UDP would not have delivered it as it is; the decoder rejects it.
  bool truncated = false;
  std::uint32_t source_ip = 0;  // host order
  std::uint32_t destination_ip = 0;
  std::uint16_t source_port = 0;
  std::uint16_t destination_port = 0;
};

// Parses `frame` (its first `frame.size()` bytes held of `wire_length` on the wire, any outer
// VLAN tag already taken out by the kernel). Nothing for a frame that is not IPv4 UDP with its
// UDP header held (another protocol, a later fragment, a header cut short).
std::optional<WireFrame> parse_wire_frame(std::span<const std::uint8_t> frame,
                                          std::size_t wire_length) noexcept;

}  // namespace pandarcap
