// The latency histogram: bucket edges, percentiles that are never below the truth and at most
// 12.5 % above it, exact power-of-two counts for the Prometheus buckets, and the extremes.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

#include "core/health/latency_histogram.hpp"

using namespace pandarcap;

TEST_CASE("latency histogram: the header's worked example", "[latency]") {
  LatencyHistogram h;
  for (int i = 0; i < 100; ++i)
    h.record(300'000);
  CHECK(h.count() == 100);
  CHECK(h.max_ns() == 300'000);
  // [294 912, 327 680) holds 300 µs; the reported quantile is the edge, capped at the max.
  CHECK(LatencyHistogram::upper_edge_ns(LatencyHistogram::bucket_of(300'000)) == 327'680);
  CHECK(h.quantile_ns(0.5) == 300'000);  // capped: every value is 300 µs
  h.record(310'000);
  CHECK(h.quantile_ns(0.5) == 310'000);  // same bucket, cap is now the new max
  h.record(2'000'000);
  CHECK(h.quantile_ns(1.0) == 2'000'000);
  CHECK(h.quantile_ns(0.5) == 327'680);
}

TEST_CASE("latency histogram: bucket edges are contiguous and increasing", "[latency]") {
  std::uint64_t previous = 0;
  for (std::size_t i = 0; i < LatencyHistogram::kBuckets; ++i) {
    const std::uint64_t edge = LatencyHistogram::upper_edge_ns(i);
    INFO("bucket " << i);
    REQUIRE(edge > previous);
    // The last value below the edge is in this bucket; the edge itself is in the next.
    CHECK(LatencyHistogram::bucket_of(edge - 1) == i);
    if (i + 1 < LatencyHistogram::kBuckets) CHECK(LatencyHistogram::bucket_of(edge) == i + 1);
    previous = edge;
  }
  CHECK(LatencyHistogram::bucket_of(0) == 0);
  CHECK(LatencyHistogram::bucket_of(std::numeric_limits<std::uint64_t>::max()) ==
        LatencyHistogram::kBuckets - 1);
}

TEST_CASE("latency histogram: percentiles bound the truth within 12.5 %", "[latency]") {
  std::mt19937_64 rng(7);
  std::lognormal_distribution<double> dist(std::log(200'000.0), 1.0);  // around 200 µs
  LatencyHistogram h;
  std::vector<std::int64_t> values;
  for (int i = 0; i < 100'000; ++i) {
    const auto v = static_cast<std::int64_t>(dist(rng)) + 1500;
    values.push_back(v);
    h.record(v);
  }
  std::sort(values.begin(), values.end());
  for (const double q : {0.5, 0.9, 0.99, 0.999}) {
    const auto rank = static_cast<std::size_t>(std::ceil(q * static_cast<double>(values.size())));
    const auto truth = static_cast<double>(values[rank - 1]);
    const auto reported = static_cast<double>(h.quantile_ns(q));
    INFO("q " << q << " truth " << truth << " reported " << reported);
    CHECK(reported >= truth);
    CHECK(reported <= truth * 1.125);
  }
  CHECK(h.max_ns() == static_cast<std::uint64_t>(values.back()));
  std::uint64_t sum = 0;
  for (const auto v : values)
    sum += static_cast<std::uint64_t>(v);
  CHECK(h.sum_ns() == sum);
  // Power-of-two counts are exact.
  for (int p = LatencyHistogram::kFirstOctave; p <= 30; ++p) {
    const auto below = static_cast<std::uint64_t>(
        std::lower_bound(values.begin(), values.end(), std::int64_t{1} << p) - values.begin());
    INFO("2^" << p);
    CHECK(h.count_below_pow2(p) == below);
  }
}

TEST_CASE("latency histogram: empty, negative and huge durations", "[latency]") {
  LatencyHistogram h;
  CHECK(h.quantile_ns(0.99) == 0);
  CHECK(h.count_below_pow2(20) == 0);
  h.record(-5);  // a receive timestamp ahead of the clock
  CHECK(h.count() == 1);
  CHECK(h.max_ns() == 0);
  CHECK(h.quantile_ns(0.5) == 0);
  h.record(std::numeric_limits<std::int64_t>::max());
  CHECK(h.count() == 2);
  CHECK(h.quantile_ns(1.0) == static_cast<std::uint64_t>(std::numeric_limits<std::int64_t>::max()));
  CHECK(h.count_below_pow2(LatencyHistogram::kFirstOctave + LatencyHistogram::kOctaves) == 1);
}
