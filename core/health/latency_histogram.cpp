#include "core/health/latency_histogram.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace pandarcap {

std::size_t LatencyHistogram::bucket_of(std::uint64_t ns) noexcept {
  if (ns < (std::uint64_t{1} << kFirstOctave)) return 0;
  const int octave = 63 - __builtin_clzll(ns);  // floor(log2 ns)
  if (octave >= kFirstOctave + kOctaves) return kBuckets - 1;
  const auto sub = static_cast<std::size_t>((ns >> (octave - 3)) & (kSubBuckets - 1));
  return 1 + static_cast<std::size_t>(octave - kFirstOctave) * kSubBuckets + sub;
}

std::uint64_t LatencyHistogram::upper_edge_ns(std::size_t i) noexcept {
  if (i == 0) return std::uint64_t{1} << kFirstOctave;
  if (i >= kBuckets - 1) return std::numeric_limits<std::uint64_t>::max();
  const std::size_t j = i - 1;
  const int octave = kFirstOctave + static_cast<int>(j / kSubBuckets);
  return (kSubBuckets + j % kSubBuckets + 1) << (octave - 3);
}

std::uint64_t LatencyHistogram::quantile_ns(double q) const noexcept {
  if (count_ == 0) return 0;
  const double wanted = std::ceil(std::clamp(q, 0.0, 1.0) * static_cast<double>(count_));
  const std::uint64_t rank = std::max<std::uint64_t>(1, static_cast<std::uint64_t>(wanted));
  std::uint64_t seen = 0;
  for (std::size_t i = 0; i < kBuckets; ++i) {
    seen += buckets_[i];
    if (seen >= rank) return std::min(upper_edge_ns(i), max_ns_);
  }
  return max_ns_;
}

std::uint64_t LatencyHistogram::count_below_pow2(int power_of_two) const noexcept {
  const int p = std::clamp(power_of_two, kFirstOctave, kFirstOctave + kOctaves);
  const std::size_t end = 1 + static_cast<std::size_t>(p - kFirstOctave) * kSubBuckets;
  std::uint64_t n = 0;
  for (std::size_t i = 0; i < end; ++i)
    n += buckets_[i];
  return n;
}

}  // namespace pandarcap
