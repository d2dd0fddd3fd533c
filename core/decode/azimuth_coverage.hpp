// Which azimuths of the rotation the packets covered: what tells a frame that lost a packet from
// a whole one, however few it lacks (core/decode/frame_assembler.hpp).
//
// Positions are the frame assembler's unwrapped block azimuth U (0.01°, growing with the
// rotation), kept for the last kWindowCdeg (four revolutions) in cells of kCellCdeg (0.1°), one
// bit each: 14 400 bits, 1.8 KB, no allocation. A reordered packet arriving late covers its
// place like any other, so a hole it fills is no hole. The window moves with the rotation:
// advance() clears the cells up to a revolution ahead of the position, so what a later
// revolution covers never reads as an earlier one's.
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

  struct Holes {
    std::int64_t total_cdeg = 0;    // the uncovered runs of at least `min_run_cdeg`, summed
    std::int64_t longest_cdeg = 0;  // the longest uncovered run
  };
  // The uncovered runs of cells inside [from, to) (within the window: the three revolutions
  // before the position).
  Holes holes(std::int64_t from, std::int64_t to, std::int64_t min_run_cdeg) const noexcept;

 private:
  static constexpr std::int64_t kCells = kWindowCdeg / kCellCdeg;
  static_assert(kCells % 64 == 0);

  bool covered(std::int64_t cell) const noexcept;
  void set(std::int64_t cell, bool covered) noexcept;

  std::array<std::uint64_t, kCells / 64> bits_{};
  std::int64_t cleared_until_ = 0;  // cells below this one are cleared up to here (a cell index)
};

}  // namespace pandarcap
