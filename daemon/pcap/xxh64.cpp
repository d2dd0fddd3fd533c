#include "daemon/pcap/xxh64.hpp"

#include <algorithm>
#include <bit>
#include <cstring>

namespace pandarcap {
namespace {

constexpr std::uint64_t kPrime1 = 0x9E3779B185EBCA87ull;
constexpr std::uint64_t kPrime2 = 0xC2B2AE3D27D4EB4Full;
constexpr std::uint64_t kPrime3 = 0x165667B19E3779F9ull;
constexpr std::uint64_t kPrime4 = 0x85EBCA77C2B2AE63ull;
constexpr std::uint64_t kPrime5 = 0x27D4EB2F165667C5ull;

std::uint64_t load64(const std::uint8_t* p) noexcept {
  std::uint64_t v = 0;
  for (int i = 7; i >= 0; --i)
    v = (v << 8) | p[i];  // little-endian whatever the host
  return v;
}

std::uint32_t load32(const std::uint8_t* p) noexcept {
  return static_cast<std::uint32_t>(p[0]) | static_cast<std::uint32_t>(p[1]) << 8 |
         static_cast<std::uint32_t>(p[2]) << 16 | static_cast<std::uint32_t>(p[3]) << 24;
}

std::uint64_t round(std::uint64_t acc, std::uint64_t input) noexcept {
  acc += input * kPrime2;
  acc = std::rotl(acc, 31);
  return acc * kPrime1;
}

std::uint64_t merge(std::uint64_t acc, std::uint64_t lane) noexcept {
  acc ^= round(0, lane);
  return acc * kPrime1 + kPrime4;
}

}  // namespace

std::array<std::uint64_t, 4> Xxh64::initial_lanes() noexcept {
  return {kPrime1 + kPrime2, kPrime2, 0, 0 - kPrime1};
}

void Xxh64::reset() noexcept {
  *this = Xxh64{};
}

void Xxh64::update(std::span<const std::uint8_t> bytes) noexcept {
  if (bytes.empty()) return;  // its data() may be null, which memcpy must not get
  total_bytes_ += bytes.size();
  const std::uint8_t* p = bytes.data();
  std::size_t n = bytes.size();
  if (stripe_bytes_ > 0) {
    const std::size_t take = std::min(n, stripe_.size() - stripe_bytes_);
    std::memcpy(stripe_.data() + stripe_bytes_, p, take);
    stripe_bytes_ += take;
    p += take;
    n -= take;
    if (stripe_bytes_ < stripe_.size()) return;
    for (std::size_t i = 0; i < 4; ++i)
      lanes_[i] = round(lanes_[i], load64(stripe_.data() + 8 * i));
    stripe_bytes_ = 0;
  }
  for (; n >= 32; p += 32, n -= 32) {
    for (std::size_t i = 0; i < 4; ++i)
      lanes_[i] = round(lanes_[i], load64(p + 8 * i));
  }
  std::memcpy(stripe_.data(), p, n);
  stripe_bytes_ = n;
}

std::uint64_t Xxh64::digest() const noexcept {
  std::uint64_t h = 0;
  if (total_bytes_ >= 32) {
    h = std::rotl(lanes_[0], 1) + std::rotl(lanes_[1], 7) + std::rotl(lanes_[2], 12) +
        std::rotl(lanes_[3], 18);
    for (const std::uint64_t lane : lanes_)
      h = merge(h, lane);
  } else {
    h = lanes_[2] + kPrime5;  // the seed (0) + prime 5
  }
  h += total_bytes_;
  const std::uint8_t* p = stripe_.data();
  std::size_t n = stripe_bytes_;
  for (; n >= 8; p += 8, n -= 8) {
    h ^= round(0, load64(p));
    h = std::rotl(h, 27) * kPrime1 + kPrime4;
  }
  if (n >= 4) {
    h ^= static_cast<std::uint64_t>(load32(p)) * kPrime1;
    h = std::rotl(h, 23) * kPrime2 + kPrime3;
    p += 4;
    n -= 4;
  }
  for (; n > 0; ++p, --n) {
    h ^= *p * kPrime5;
    h = std::rotl(h, 11) * kPrime1;
  }
  h ^= h >> 33;
  h *= kPrime2;
  h ^= h >> 29;
  h *= kPrime3;
  h ^= h >> 32;
  return h;
}

std::array<std::uint8_t, 4> zstd_content_checksum(const Xxh64& hash) noexcept {
  const std::uint64_t h = hash.digest();
  return {static_cast<std::uint8_t>(h), static_cast<std::uint8_t>(h >> 8),
          static_cast<std::uint8_t>(h >> 16), static_cast<std::uint8_t>(h >> 24)};
}

}  // namespace pandarcap
