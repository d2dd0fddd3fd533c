// Which azimuths of the rotation the packets covered: what tells a frame that lost a packet from
// a whole one, however few it lacks (core/decode/frame_assembler.hpp). And which the stream
// decoder left out on purpose (an outlier that could not be repaired): not covered, so the frame
// is partial, but not lost either, so not counted as missing.
//
// Positions are the frame assembler's unwrapped block azimuth U (0.01°, growing with the
// rotation), kept for the last kWindowCdeg (four revolutions) in cells of kCellCdeg (0.1°), one
// bit each for covered and for left out: 2 x 14 400 bits, 3.6 KB, no allocation. A reordered packet
// arriving late covers its place like any other, so a hole it fills is no hole. The window moves
// with the rotation: advance() clears the cells up to a revolution ahead of the position, so what a
// later revolution covers never reads as an earlier one's.
#pragma once

#include <array>
#include <cstdint>

namespace pandarcap {

class AzimuthCoverage {
 public:
  static constexpr std::int64_t kCellCdeg = 10;
  static constexpr std::int64_t kWindowCdeg = 4 * 36000;

  // Forgets everything (a new stream starting at `position`).
  void reset(std::int64_t position) noexcept;
  // The rotation reached `position`: cells up to a revolution ahead of it are cleared.
  void advance(std::int64_t position) noexcept;
  // [from, to) was covered: every cell it touches.
  void cover(std::int64_t from, std::int64_t to) noexcept;
  // [from, to) was left out on purpose: every cell it touches.
  void leave_out(std::int64_t from, std::int64_t to) noexcept;

  // How holes are counted in packets: a run of uncovered azimuth `run` wide is what
  // llround((run + widen_cdeg) / packet_step_cdeg) packets leave (each packet covers its step and
  // a margin either side, so n lost packets leave n steps less the margins: `widen_cdeg`).
  struct PacketSize {
    double packet_step_cdeg = 100;
    double widen_cdeg = 20;
  };
  // The packets lost in the runs that begin inside [from, to) and are neither covered nor left
  // out, of at least `min_run_cdeg`, each measured whole (up to `until`): a run is counted once,
  // by the range it begins in, however it is split into frames.
  std::uint64_t lost_packets(std::int64_t from, std::int64_t to, std::int64_t until,
                             std::int64_t min_run_cdeg, const PacketSize& size) const noexcept;
  // The longest run inside [from, to) not covered (left out or lost).
  std::int64_t longest_uncovered_cdeg(std::int64_t from, std::int64_t to) const noexcept;

 private:
  static constexpr std::int64_t kCells = kWindowCdeg / kCellCdeg;
  static_assert(kCells % 64 == 0);
  using Bits = std::array<std::uint64_t, kCells / 64>;

  static bool test(const Bits& bits, std::int64_t cell) noexcept;
  static void set(Bits& bits, std::int64_t cell, bool on) noexcept;
  void mark(Bits& bits, std::int64_t from, std::int64_t to) noexcept;

  Bits bits_{};
  Bits left_out_{};
  std::int64_t cleared_until_ = 0;  // cells below this one are cleared up to here (a cell index)
};

}  // namespace pandarcap
