// What the outlier rule (core/decode/stream_decoder.hpp) compares and keeps: where a packet sits in
// the rotation, whether one packet follows another, and the packets held back while the rule cannot
// yet tell a glitch from a real change.
//
// A glitch is a run of up to kMaxHeldPackets consecutive packets that do not follow the stream:
// their time back or forward, their azimuth shifted, their date a second off, their time zeroed.
// A real change (a restart, a long gap, a new speed, a clock that stepped for good) is a run
// that goes on: kChangeRunPackets packets that follow each other and not the stream. Held
// packets wait in a fixed buffer (no allocation), at most kMaxHeldPackets of them: 16 packets
// are 4.4 ms of a dual-return stream, 8.9 ms of a single-return one.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

#include "core/decode/packet_time.hpp"
#include "core/sensors/packet.hpp"

namespace pandarcap {

inline constexpr std::size_t kMaxHeldPackets = 16;
inline constexpr std::size_t kChangeRunPackets = kMaxHeldPackets + 1;

// Where a packet sits in the rotation: what follows() compares.
struct RotationPoint {
  std::uint16_t azimuth_cdeg = 0;  // the first block's
  std::int64_t t0_ns = 0;
  bool time_valid = false;
  std::uint16_t rpm = 0;  // the tail's motor speed
};

// Whether `next` follows `last` in one rotation. With valid times that moved, the azimuth must
// have advanced by what the time took at `last`'s speed (within 2° + 2 %), and by less than half
// a revolution: a packet loss, a reordered pair and a slow speed change all follow; a time that
// leaps or goes back, an azimuth out of order do not. A valid time never follows an invalid one,
// nor the other way round: one of the two clocks is broken. Without usable times (both invalid,
// frozen, no speed), the azimuth alone: a step of at most 90° either way.
bool follows(const RotationPoint& last, const RotationPoint& next) noexcept;

// a - b on the circle, in [-18000, 18000) (0.01°).
int signed_step_cdeg(int a, int b) noexcept;

// A packet accepted and timed, on its way to be placed (or held back).
struct AdmittedPacket {
  RotationPoint rotation;
  PacketTime time;
};

// The held-back packets, oldest first: copies of their bytes and what the rule knows of them.
// The newest ones that follow each other form the chain, the candidate for a real change; the
// older ones (strays) followed neither the stream nor the chain.
class HeldPackets {
 public:
  bool empty() const noexcept { return count_ == 0; }
  bool full() const noexcept { return count_ == kMaxHeldPackets; }
  std::size_t size() const noexcept { return count_; }
  // i: 0 = the oldest held.
  std::span<const std::uint8_t> bytes(std::size_t i) const noexcept {
    const Entry& e = at(i);
    return {e.bytes.data(), e.size};
  }
  const AdmittedPacket& admitted(std::size_t i) const noexcept { return at(i).admitted; }
  // The chain: the held packets from chain_start() on.
  std::size_t chain_start() const noexcept { return chain_start_; }
  std::size_t chain_length() const noexcept { return count_ - chain_start_; }
  const AdmittedPacket& newest() const noexcept { return at(count_ - 1).admitted; }

  // Holds a copy of `payload` (not full()). `extends_chain`: it follows the chain's newest;
  // otherwise it starts a new chain and every packet held before it is a stray.
  void push(std::span<const std::uint8_t> payload, const AdmittedPacket& admitted,
            bool extends_chain) noexcept;
  // Forgets the oldest (a stray: chain_start() > 0).
  void pop_oldest() noexcept;
  void clear() noexcept { head_ = count_ = chain_start_ = 0; }

 private:
  struct Entry {
    std::array<std::uint8_t, kMaxPacketBytes> bytes;
    std::size_t size = 0;
    AdmittedPacket admitted;
  };
  const Entry& at(std::size_t i) const noexcept { return entries_[(head_ + i) % kMaxHeldPackets]; }

  std::array<Entry, kMaxHeldPackets> entries_{};
  std::size_t head_ = 0, count_ = 0, chain_start_ = 0;
};

}  // namespace pandarcap
