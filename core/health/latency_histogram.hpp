// A fixed-size log-linear histogram of durations: how long packets took from the kernel's receive
// timestamp to decoded. It is recorded on the decode thread with no allocation and no lock, copied
// into the health snapshot once a second, and rendered as a Prometheus histogram and as
// percentiles in the JSON line.
//
// Buckets: everything below 1 µs in one; from 1 µs up, each power of two is split into 8 equal
// buckets, so a reported percentile (the upper edge of its bucket) overstates the true value by
// at most 12.5 %. The top bucket (2^34 ns ≈ 17 s and above) is open-ended; `max_ns` is exact.
//
// Example: 300 µs = 300 000 ns lies in [2^18, 2^19) (262 144 .. 524 288 ns), in the second of its
// 8 sub-buckets, [294 912, 327 680): p50 of a run of 300 µs latencies is reported as 327.68 µs.
#pragma once

#include <array>
#include <cstdint>

namespace pandarcap {

class LatencyHistogram {
 public:
  static constexpr int kSubBuckets = 8;    // per power of two
  static constexpr int kFirstOctave = 10;  // 2^10 ns ≈ 1 µs
  static constexpr int kOctaves = 24;      // up to 2^34 ns ≈ 17 s
  static constexpr std::size_t kBuckets = 1 + kOctaves * kSubBuckets + 1;

  // Negative durations (a receive timestamp ahead of the clock) count as 0.
  void record(std::int64_t ns) noexcept {
    const std::uint64_t v = ns > 0 ? static_cast<std::uint64_t>(ns) : 0;
    ++buckets_[bucket_of(v)];
    ++count_;
    sum_ns_ += v;
    if (v > max_ns_) max_ns_ = v;
  }

  std::uint64_t count() const noexcept { return count_; }
  std::uint64_t sum_ns() const noexcept { return sum_ns_; }
  std::uint64_t max_ns() const noexcept { return max_ns_; }

  // The upper edge of the bucket holding the q-quantile (0 < q <= 1), capped at max_ns; 0 when
  // empty.
  std::uint64_t quantile_ns(double q) const noexcept;

  // How many durations were below 2^power_of_two ns (exact: powers of two are bucket edges), for
  // power_of_two in kFirstOctave .. kFirstOctave + kOctaves.
  std::uint64_t count_below_pow2(int power_of_two) const noexcept;

  // Upper edge (exclusive) of bucket i, in ns; the last bucket's is the largest uint64.
  static std::uint64_t upper_edge_ns(std::size_t i) noexcept;
  static std::size_t bucket_of(std::uint64_t ns) noexcept;

 private:
  std::array<std::uint64_t, kBuckets> buckets_{};
  std::uint64_t count_ = 0;
  std::uint64_t sum_ns_ = 0;
  std::uint64_t max_ns_ = 0;
};

}  // namespace pandarcap
