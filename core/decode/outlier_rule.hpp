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
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <optional>
#include <span>

#include "core/decode/packet_time.hpp"
#include "core/sensors/model_access.hpp"
#include "core/sensors/packet.hpp"
#include "core/sensors/sensor_model.hpp"

namespace pandarcap {

inline constexpr std::size_t kMaxHeldPackets = 16;
inline constexpr std::size_t kChangeRunPackets = kMaxHeldPackets + 1;

// Where a packet sits in the rotation: what follows() compares.
struct RotationPoint {
  std::uint16_t azimuth_cdeg = 0;  // the first block's
  std::int64_t t0_ns = 0;
  bool time_valid = false;
  std::uint16_t rpm = 0;  // the tail's motor speed
  // Its time was the packet's placed before it (a clock that froze): not one to judge by.
  bool time_stood = false;
};

// Which way a rotation turns: as the sensor's does (azimuth growing with time), or backwards (a
// stream whose azimuth runs down; no 40P does it, a broken encoder or a hostile sender may).
enum class Turning : std::int8_t { kForward = 1, kBackward = -1 };

// Whether `next` follows `last` in one rotation turning `turning`. With valid times that moved,
// the azimuth must have advanced (or, backwards, gone back) by what the time took at `last`'s
// speed (or at `next`'s, the stream's speed having just changed), within follow_tolerance_cdeg()
// (core/sensors/sensor_model.hpp: 0.06° for one dual packet), and by less than half a revolution: a
// packet loss, a reordered pair and a slow speed change follow; a time that leaps or goes back, an
// azimuth shifted by 0.1° or more do not. A valid time never follows an invalid one, nor the other
// way round: one of the two clocks is broken. Without usable times (both invalid, frozen: `last`'s
// time stood or `next`'s is the same, no speed), the azimuth alone: a step of at most 90° either
// way.
bool follows(const RotationPoint& last, const RotationPoint& next,
             Turning turning = Turning::kForward) noexcept;

// a - b on the circle, in [-18000, 18000) (0.01°).
int signed_step_cdeg(int a, int b) noexcept;

// A packet accepted and timed, on its way to be placed (or held back).
struct AdmittedPacket {
  RotationPoint rotation;
  PacketTime time;
  std::int64_t period_ns = 0;  // the sensor's packet period in its return mode
  std::uint64_t arrival = 0;   // which packet accepted it was (StreamStats::accepted then)
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
  // The chain: the held packets from chain_start() on, and which way they turn (none yet for a
  // chain of one).
  std::size_t chain_start() const noexcept { return chain_start_; }
  std::size_t chain_length() const noexcept { return count_ - chain_start_; }
  std::optional<Turning> chain_turning() const noexcept { return chain_turning_; }
  const AdmittedPacket& newest() const noexcept { return at(count_ - 1).admitted; }
  // Strays forgotten since the run began (pop_oldest()): the held packets' places in the run
  // come after them.
  std::size_t forgotten() const noexcept { return forgotten_; }

  // Holds a copy of `payload` (not full()). `extends`: the way it follows the chain's newest;
  // none: it starts a new chain and every packet held before it is a stray.
  void push(std::span<const std::uint8_t> payload, const AdmittedPacket& admitted,
            std::optional<Turning> extends) noexcept;
  // Puts held packet i's first block at `first_cdeg`: an outlier whose time says where it
  // belongs, repaired in the copy before it is placed. Every block moves by the same shift when
  // the packet's own blocks are a packet's span apart (`packet_step_cdeg`, within
  // follow_tolerance_cdeg()): an azimuth shifted whole keeps its encoder's readings. Otherwise
  // (every block the same garbage) each block's azimuth is where its firing round was.
  template <class Model>
  void move_azimuth(std::size_t i, int first_cdeg, double packet_step_cdeg) noexcept {
    Entry& e = at(i);
    const std::span<const std::uint8_t> p(e.bytes.data(), e.size);
    const int rounds = Model::firings_per_packet(returns_per_firing(Model::return_mode(p)));
    const int pairing = Model::kBlocks / rounds;  // blocks a firing round gives (2 in dual)
    const double round_step = packet_step_cdeg / rounds;
    const double span = round_step * (rounds - 1);
    const int own_span =
        signed_step_cdeg(Model::azimuth_cdeg(p, Model::kBlocks - 1), Model::azimuth_cdeg(p, 0));
    const bool whole = std::abs(own_span - span) <= follow_tolerance_cdeg(span);
    const int shift = first_cdeg - Model::azimuth_cdeg(p, 0);
    std::array<int, Model::kBlocks> azimuths{};
    for (int b = 0; b < Model::kBlocks; ++b) {
      azimuths[b] = whole ? Model::azimuth_cdeg(p, b) + shift
                          : first_cdeg + static_cast<int>(std::lround(round_step * (b / pairing)));
    }
    for (int b = 0; b < Model::kBlocks; ++b) {
      const auto azimuth = static_cast<std::uint16_t>((azimuths[b] % 36000 + 36000) % 36000);
      std::uint8_t* field = e.bytes.data() + block_azimuth_offset<Model>(p, b);
      field[0] = static_cast<std::uint8_t>(azimuth);
      field[1] = static_cast<std::uint8_t>(azimuth >> 8);
    }
    e.admitted.rotation.azimuth_cdeg = static_cast<std::uint16_t>(azimuths[0] % 36000);
  }
  // Forgets the oldest (a stray: chain_start() > 0).
  void pop_oldest() noexcept;
  void clear() noexcept {
    head_ = count_ = chain_start_ = forgotten_ = 0;
    chain_turning_.reset();
  }

 private:
  struct Entry {
    std::array<std::uint8_t, kMaxPacketBytes> bytes;
    std::size_t size = 0;
    AdmittedPacket admitted;
  };
  const Entry& at(std::size_t i) const noexcept { return entries_[(head_ + i) % kMaxHeldPackets]; }
  Entry& at(std::size_t i) noexcept { return entries_[(head_ + i) % kMaxHeldPackets]; }

  std::array<Entry, kMaxHeldPackets> entries_{};
  std::size_t head_ = 0, count_ = 0, chain_start_ = 0, forgotten_ = 0;
  std::optional<Turning> chain_turning_;
};

}  // namespace pandarcap
