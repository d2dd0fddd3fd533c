// CRC-32/MPEG-2, the checksum Hesai's newer packets carry (the PandarQT128's body, functional-
// safety block and tail; the JT16's packet): polynomial 0x04C11DB7, initial value 0xFFFFFFFF,
// neither input nor output reflected, no final XOR. The packets store it little-endian.
// Check value: crc32_mpeg2("123456789") = 0x0376E6E7.
#pragma once

#include <array>
#include <cstdint>
#include <span>

namespace pandarcap {

inline constexpr std::array<std::uint32_t, 256> kCrc32Mpeg2Table = [] {
  std::array<std::uint32_t, 256> table{};
  for (std::uint32_t i = 0; i < 256; ++i) {
    std::uint32_t crc = i << 24;
    for (int bit = 0; bit < 8; ++bit)
      crc = (crc & 0x80000000u) != 0 ? (crc << 1) ^ 0x04C11DB7u : crc << 1;
    table[i] = crc;
  }
  return table;
}();

constexpr std::uint32_t crc32_mpeg2(std::span<const std::uint8_t> bytes) noexcept {
  std::uint32_t crc = 0xFFFFFFFFu;
  for (const std::uint8_t byte : bytes)
    crc = (crc << 8) ^ kCrc32Mpeg2Table[((crc >> 24) ^ byte) & 0xFFu];
  return crc;
}

}  // namespace pandarcap
