#include "core/decode/azimuth_coverage.hpp"

#include <algorithm>

namespace pandarcap {

namespace {

std::int64_t floor_div(std::int64_t a, std::int64_t b) noexcept {
  const std::int64_t q = a / b;
  return (a % b != 0 && (a < 0) != (b < 0)) ? q - 1 : q;
}

constexpr std::int64_t kRevolutionCells = 36000 / AzimuthCoverage::kCellCdeg;

}  // namespace

bool AzimuthCoverage::covered(std::int64_t cell) const noexcept {
  const auto i = static_cast<std::uint64_t>(((cell % kCells) + kCells) % kCells);
  return (bits_[i / 64] >> (i % 64)) & 1u;
}

void AzimuthCoverage::set(std::int64_t cell, bool on) noexcept {
  const auto i = static_cast<std::uint64_t>(((cell % kCells) + kCells) % kCells);
  const std::uint64_t mask = std::uint64_t{1} << (i % 64);
  bits_[i / 64] = on ? (bits_[i / 64] | mask) : (bits_[i / 64] & ~mask);
}

void AzimuthCoverage::reset(std::int64_t position) noexcept {
  bits_.fill(0);
  cleared_until_ = floor_div(position, kCellCdeg) + kRevolutionCells;
}

void AzimuthCoverage::advance(std::int64_t position) noexcept {
  const std::int64_t target = floor_div(position, kCellCdeg) + kRevolutionCells;
  if (target <= cleared_until_) return;
  if (target - cleared_until_ >= kCells) {
    bits_.fill(0);
  } else {
    for (std::int64_t cell = cleared_until_; cell < target; ++cell)
      set(cell, false);
  }
  cleared_until_ = target;
}

void AzimuthCoverage::cover(std::int64_t from, std::int64_t to) noexcept {
  if (to <= from) return;
  // Only cells of the window that advance() has cleared: a packet far ahead (a discontinuity
  // the caller has not seen yet) must not mark a later revolution.
  const std::int64_t last = std::min(floor_div(to - 1, kCellCdeg), cleared_until_ - 1);
  const std::int64_t first = std::max(floor_div(from, kCellCdeg), cleared_until_ - kCells);
  for (std::int64_t cell = first; cell <= last; ++cell)
    set(cell, true);
}

AzimuthCoverage::Holes AzimuthCoverage::holes(std::int64_t from, std::int64_t to,
                                              std::int64_t min_run_cdeg) const noexcept {
  Holes holes;
  const std::int64_t first = std::max(floor_div(from, kCellCdeg), cleared_until_ - kCells);
  const std::int64_t end = floor_div(to - 1, kCellCdeg) + 1;
  std::int64_t run = 0;
  const auto close_run = [&] {
    const std::int64_t cdeg = run * kCellCdeg;
    if (cdeg >= min_run_cdeg) holes.total_cdeg += cdeg;
    holes.longest_cdeg = std::max(holes.longest_cdeg, cdeg);
    run = 0;
  };
  for (std::int64_t cell = first; cell < end; ++cell) {
    if (covered(cell)) {
      close_run();
    } else {
      ++run;
    }
  }
  close_run();
  return holes;
}

}  // namespace pandarcap
