#include "core/decode/azimuth_coverage.hpp"

#include <algorithm>
#include <cmath>

#include "core/floor_div.hpp"

namespace pandarcap {

namespace {

constexpr std::int64_t kRevolutionCells = 36000 / AzimuthCoverage::kCellCdeg;

}  // namespace

bool AzimuthCoverage::test(const Bits& bits, std::int64_t cell) noexcept {
  const auto i = static_cast<std::uint64_t>(((cell % kCells) + kCells) % kCells);
  return (bits[i / 64] >> (i % 64)) & 1u;
}

void AzimuthCoverage::set(Bits& bits, std::int64_t cell, bool on) noexcept {
  const auto i = static_cast<std::uint64_t>(((cell % kCells) + kCells) % kCells);
  const std::uint64_t mask = std::uint64_t{1} << (i % 64);
  bits[i / 64] = on ? (bits[i / 64] | mask) : (bits[i / 64] & ~mask);
}

void AzimuthCoverage::reset(std::int64_t position) noexcept {
  bits_.fill(0);
  left_out_.fill(0);
  cleared_until_ = floor_div(position, kCellCdeg) + kRevolutionCells;
}

void AzimuthCoverage::advance(std::int64_t position) noexcept {
  const std::int64_t target = floor_div(position, kCellCdeg) + kRevolutionCells;
  if (target <= cleared_until_) return;
  if (target - cleared_until_ >= kCells) {
    bits_.fill(0);
    left_out_.fill(0);
  } else {
    for (std::int64_t cell = cleared_until_; cell < target; ++cell) {
      set(bits_, cell, false);
      set(left_out_, cell, false);
    }
  }
  cleared_until_ = target;
}

void AzimuthCoverage::mark(Bits& bits, std::int64_t from, std::int64_t to) noexcept {
  if (to <= from) return;
  // Only cells of the window that advance() has cleared: a packet far ahead (a discontinuity
  // the caller has not seen yet) must not mark a later revolution.
  const std::int64_t last = std::min(floor_div(to - 1, kCellCdeg), cleared_until_ - 1);
  const std::int64_t first = std::max(floor_div(from, kCellCdeg), cleared_until_ - kCells);
  for (std::int64_t cell = first; cell <= last; ++cell)
    set(bits, cell, true);
}

void AzimuthCoverage::cover(std::int64_t from, std::int64_t to) noexcept {
  mark(bits_, from, to);
}

void AzimuthCoverage::leave_out(std::int64_t from, std::int64_t to) noexcept {
  mark(left_out_, from, to);
}

std::uint64_t AzimuthCoverage::lost_packets(std::int64_t from, std::int64_t to, std::int64_t until,
                                            std::int64_t min_run_cdeg,
                                            const PacketSize& size) const noexcept {
  const std::int64_t window_first = cleared_until_ - kCells;
  const std::int64_t first = std::max(floor_div(from, kCellCdeg), window_first);
  const std::int64_t end = floor_div(to - 1, kCellCdeg) + 1;
  const std::int64_t last = std::max(end, floor_div(until - 1, kCellCdeg) + 1);
  const auto lost = [&](std::int64_t cell) { return !test(bits_, cell) && !test(left_out_, cell); };
  std::uint64_t packets = 0;
  std::int64_t cell = first;
  // A run already open at `from` began in the range before: that range counts it.
  if (cell > window_first) {
    while (cell < end && lost(cell - 1) && lost(cell))
      ++cell;
  }
  while (cell < end) {
    if (!lost(cell)) {
      ++cell;
      continue;
    }
    std::int64_t run = 0;
    while (cell < last && lost(cell)) {
      ++run;
      ++cell;
    }
    const std::int64_t cdeg = run * kCellCdeg;
    if (cdeg >= min_run_cdeg) {
      packets += static_cast<std::uint64_t>(
          std::llround((static_cast<double>(cdeg) + size.widen_cdeg) / size.packet_step_cdeg));
    }
  }
  return packets;
}

std::int64_t AzimuthCoverage::longest_uncovered_cdeg(std::int64_t from,
                                                     std::int64_t to) const noexcept {
  const std::int64_t first = std::max(floor_div(from, kCellCdeg), cleared_until_ - kCells);
  const std::int64_t end = floor_div(to - 1, kCellCdeg) + 1;
  std::int64_t run = 0, longest = 0;
  for (std::int64_t cell = first; cell < end; ++cell) {
    run = test(bits_, cell) ? 0 : run + 1;
    longest = std::max(longest, run);
  }
  return longest * kCellCdeg;
}

}  // namespace pandarcap
