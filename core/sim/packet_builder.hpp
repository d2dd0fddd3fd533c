// Encodes packet fields into wire bytes: the inverse of PacketView. Used by the synthetic
// sensor and by tests that craft packets (a test then corrupts single bytes to make bad ones).
#pragma once

#include <array>
#include <cstdint>
#include <span>

#include "core/sensors/packet.hpp"

namespace pandarcap {

struct PacketContents {
  std::array<std::uint16_t, kBlocks> azimuth_cdeg{};
  std::array<std::array<std::uint16_t, kChannels>, kBlocks> distance_raw{};
  std::array<std::array<std::uint8_t, kChannels>, kBlocks> reflectivity{};
  Tail tail;  // tail.sequence set -> a 1266-byte packet
};

// Writes the packet (markers FF EE in every block) and returns its size, 1262 or 1266.
std::size_t encode(const PacketContents& contents, std::span<std::uint8_t, kMaxPacketBytes> out);

}  // namespace pandarcap
