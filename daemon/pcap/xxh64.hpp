// XXH64 (seed 0) as a running state: the hash a zstd frame's content checksum is made of (RFC 8878
// 3.1.1: the checksum is the low 4 bytes of XXH64 of the decompressed content, little-endian).
// ZstdStreamCompressor keeps one beside zstd's own, so that a frame cut back to a flush (a full
// disk) can still be ended with the checksum of what it holds; libzstd does not expose its state.
// Fixed size, no allocation: safe in the writer's loop. Checked against zstd's own checksums.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

namespace pandarcap {

class Xxh64 {
 public:
  void reset() noexcept;
  void update(std::span<const std::uint8_t> bytes) noexcept;
  std::uint64_t digest() const noexcept;  // of everything given since reset()

 private:
  std::array<std::uint64_t, 4> lanes_ = initial_lanes();
  std::uint64_t total_bytes_ = 0;
  std::array<std::uint8_t, 32> stripe_{};  // a stripe not yet whole
  std::size_t stripe_bytes_ = 0;

  static std::array<std::uint64_t, 4> initial_lanes() noexcept;
};

// The 4 bytes a zstd frame with a content checksum ends with, for content hashed as `hash`.
std::array<std::uint8_t, 4> zstd_content_checksum(const Xxh64& hash) noexcept;

}  // namespace pandarcap
