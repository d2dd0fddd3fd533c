// Fuzz target: a frame as a packet socket hands it over (core/wire_frame.hpp), the packet_ring
// receiver's only reading of bytes off the wire. The first two bytes give the wire length's
// excess over the bytes held (a snapped frame). Invariants: never a read outside the frame
// (ASan), and the lengths it returns stay inside it.
#include <cstdint>
#include <cstdlib>
#include <span>

#include "core/wire_frame.hpp"

using namespace pandarcap;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 2) return 0;
  const std::size_t excess = static_cast<std::size_t>(data[0]) << 8 | data[1];
  const std::span<const std::uint8_t> frame(data + 2, size - 2);
  const auto w = parse_wire_frame(frame, frame.size() + excess);
  if (!w) return 0;
  if (w->header_bytes + w->payload_bytes + w->trailer_bytes != frame.size()) std::abort();
  if (w->payload_bytes > w->claimed_bytes || w->arrived_bytes > w->claimed_bytes) std::abort();
  if (!w->truncated && w->payload_bytes != w->claimed_bytes) std::abort();
  return 0;
}
