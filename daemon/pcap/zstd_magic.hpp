// The bytes a zstd frame starts with: how a capture file is recognised as compressed, and where
// the recovery of a cut .pcap.zst looks for its frames.
#pragma once

#include <array>
#include <cstdint>

namespace pandarcap {

// The zstd frame magic number as it starts a file (RFC 8878 3.1.1: 0xFD2FB528, little-endian).
inline constexpr std::array<std::uint8_t, 4> kZstdMagic{0x28, 0xB5, 0x2F, 0xFD};

}  // namespace pandarcap
