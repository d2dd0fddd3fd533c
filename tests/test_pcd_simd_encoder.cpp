// The SIMD PCD encoder against the scalar reference (encode_pcd_points), on every target this
// machine runs: the same bytes for every layout and axes, edge values, every count from 0 to a
// few vectors (so every partial last vector), times that leave the call's second or come before
// 1970, and nothing written past the points.
#include <catch2/catch.hpp>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "core/decode/decoder_target.hpp"
#include "core/decode/pcd_simd_encoder.hpp"
#include "core/decode/simd_decoder.hpp"
#include "core/frames/pcd.hpp"

using namespace pandarcap;

namespace {

std::vector<DecoderTarget> encoder_targets() {
  std::vector<DecoderTarget> targets = supported_decoder_targets();
  targets.erase(targets.begin());  // scalar, the reference
  return targets;
}

constexpr PcdLayout kSimdLayouts[] = {PcdLayout::kPcl, PcdLayout::kPandarcap, PcdLayout::kVelodyne,
                                      PcdLayout::kAutoware};
constexpr std::size_t kCanary = 40;  // bytes after the points that must stay untouched

// Encodes `points` with both and requires the same bytes, and the canary after them intact.
void require_same_encoding(const PcdEncoder& encoder, std::span<const Point> points,
                           PcdFormat format, PcdFrameContext frame, const std::string& what) {
  const std::size_t step = pcd_point_bytes(format.layout);
  const std::size_t bytes = points.size() * step;
  std::vector<std::uint8_t> expected(bytes + kCanary, 0xCD), actual(bytes + kCanary, 0xCD);
  const std::size_t e = encode_pcd_points(points, std::span(expected).first(bytes), format, frame);
  const std::size_t a = encoder.encode(points, std::span(actual).first(bytes), format, frame);
  INFO(what << ": " << to_string(encoder.target()) << ", " << to_string(format.layout) << ", "
            << to_string(format.axes) << ", " << points.size() << " points");
  REQUIRE(a == e);
  REQUIRE(e == bytes);
  if (expected == actual) return;
  const auto at = static_cast<std::size_t>(
      std::mismatch(expected.begin(), expected.end(), actual.begin()).first - expected.begin());
  INFO("first difference at point " << at / step << ", byte " << at % step << " of its row"
                                    << (at >= bytes ? " (past the points)" : ""));
  FAIL("the SIMD encoder's bytes differ from the reference's");
}

float float_from_bits(std::uint32_t bits) {
  float f;
  std::memcpy(&f, &bits, sizeof f);
  return f;
}

// Points with every field at its edges, around `time_ns`.
std::vector<Point> edge_points(std::int64_t time_ns) {
  const float specials[] = {0.0f,
                            -0.0f,
                            1.5f,
                            -123.456f,
                            std::numeric_limits<float>::quiet_NaN(),
                            float_from_bits(0xFFC12345),  // a negative NaN with a payload
                            std::numeric_limits<float>::infinity(),
                            -std::numeric_limits<float>::infinity(),
                            std::numeric_limits<float>::denorm_min(),
                            std::numeric_limits<float>::max(),
                            199.996f};
  const std::int64_t times[] = {time_ns,
                                time_ns - time_ns % 1'000'000'000,  // the second itself
                                time_ns - time_ns % 1'000'000'000 + 999'999'999, time_ns + 1,
                                time_ns - 1};
  std::vector<Point> points;
  std::size_t k = 0;
  for (const float x : specials) {
    for (const float y : specials) {
      Point p;
      p.x = x;
      p.y = y;
      p.z = specials[(k * 7) % std::size(specials)];
      p.distance_m = specials[(k * 5) % std::size(specials)];
      p.timestamp_ns = times[k % std::size(times)];
      p.azimuth_cdeg = static_cast<std::uint16_t>(k % 3 == 0 ? 35'999 : k % 3 == 1 ? 0 : 65'535);
      p.intensity = static_cast<std::uint8_t>(k % 2 == 0 ? 255 : k);
      p.channel = static_cast<std::uint8_t>(k % 4 == 0   ? 39
                                            : k % 4 == 1 ? 0
                                            : k % 4 == 2 ? 255
                                                         : k);
      // 0..3 and an invalid 7 (the reference writes it as it is; nebula's code for it is 0).
      p.return_type = static_cast<ReturnType>(k % 5 == 4 ? 7 : k % 5);
      points.push_back(p);
      ++k;
    }
  }
  return points;
}

// A revolution's worth of plausible points, their times spread over `spread_ns` from `t0_ns`.
std::vector<Point> random_points(std::mt19937_64& rng, std::size_t n, std::int64_t t0_ns,
                                 std::int64_t spread_ns) {
  std::uniform_real_distribution<float> coordinate(-200.0f, 200.0f);
  std::uniform_int_distribution<std::int64_t> offset(0, spread_ns);
  std::uniform_int_distribution<int> byte(0, 255), azimuth(0, 35'999), type(0, 3);
  std::vector<Point> points(n);
  for (Point& p : points) {
    p.x = coordinate(rng);
    p.y = coordinate(rng);
    p.z = coordinate(rng) / 10;
    p.distance_m = std::sqrt(p.x * p.x + p.y * p.y + p.z * p.z);
    p.timestamp_ns = t0_ns + offset(rng);
    p.azimuth_cdeg = static_cast<std::uint16_t>(azimuth(rng));
    p.intensity = static_cast<std::uint8_t>(byte(rng));
    p.channel = static_cast<std::uint8_t>(byte(rng) % 40);
    p.return_type = static_cast<ReturnType>(type(rng));
  }
  return points;
}

}  // namespace

TEST_CASE("PCD SIMD encoder: a kernel for every compiled target, no silent fallback",
          "[simd][pcd]") {
  for (const DecoderTarget target : compiled_decoder_targets()) {
    INFO(to_string(target));
    CHECK((pcd_encode_kernel(target) != nullptr) == (target != DecoderTarget::kScalar));
  }
  for (const DecoderTarget target : supported_decoder_targets()) {
    CHECK(PcdEncoder(target).target() == target);
  }
  CHECK(PcdEncoder().target() == best_decoder_target());
}

TEST_CASE("PCD SIMD encoder: the reference's bytes, every layout and axes, edge values and counts",
          "[simd][pcd]") {
  const std::vector<DecoderTarget> targets = encoder_targets();
  if (targets.empty()) WARN("no SIMD target on this CPU: nothing to compare");
  std::mt19937_64 rng(40);
  const std::int64_t t = 1'795'348'800'123'456'789;
  const std::vector<Point> edges = edge_points(t);
  // A block of a frame that crosses a second, and a frame's worth spread over 0.3 s around it.
  const std::vector<Point> crossing = random_points(rng, 64, 1'795'348'800'999'990'000, 20'000);
  const std::vector<Point> frame = random_points(rng, 4000, 1'795'348'800'850'000'000, 300'000'000);
  for (const DecoderTarget target : targets) {
    const PcdEncoder encoder(target);
    REQUIRE(encoder.target() == target);
    for (const PcdLayout layout : kSimdLayouts) {
      for (const Axes axes : {Axes::kHesai, Axes::kRos}) {
        const PcdFormat format{layout, axes};
        for (const ReturnMode mode :
             {ReturnMode::kDual, ReturnMode::kStrongest, ReturnMode::kLast}) {
          const PcdFrameContext context{t - 2'500'000, mode};
          require_same_encoding(encoder, edges, format, context, "edge values");
        }
        const PcdFrameContext context{t, ReturnMode::kDual};
        // Every count up to four 8-lane vectors and one more, from every start: each partial
        // last vector, and the rows on either side of it.
        for (std::size_t n = 0; n <= 33; ++n) {
          for (std::size_t from = 0; from + n <= edges.size() && from < 9; ++from) {
            require_same_encoding(encoder, std::span(edges).subspan(from, n), format, context,
                                  "counts");
          }
        }
        require_same_encoding(encoder, crossing, format, context, "a second boundary");
        require_same_encoding(encoder, frame, format,
                              {frame.front().timestamp_ns, ReturnMode::kDual}, "a frame");
      }
    }
  }
}

TEST_CASE("PCD SIMD encoder: times the kernel leaves to the reference come out the same",
          "[simd][pcd]") {
  const std::vector<DecoderTarget> targets = encoder_targets();
  if (targets.empty()) WARN("no SIMD target on this CPU: nothing to compare");
  std::mt19937_64 rng(41);
  struct Case {
    const char* what;
    std::int64_t t0_ns, spread_ns, reference_ns;
  };
  const Case cases[] = {
      {"before 1970", -1'500'000'000, 1'000'000, -1'500'000'000},
      {"either side of the epoch", -500'000, 1'000'000, -500'000},
      {"the epoch itself", 0, 1'000, 0},
      {"an unsynchronised sensor clock (2017)", 1'504'656'000'999'000'000, 3'000'000,
       1'504'656'001'000'000'000},
      {"before the frame's reference (a reordered packet)", 1'795'348'800'100'000'000, 50'000'000,
       1'795'348'800'140'000'000},
      {"past 2^32 ns after the reference", 1'795'348'805'000'000'000, 1'000'000,
       1'795'348'800'000'000'000},
      {"2^51 ns and more from the reference", std::int64_t{1} << 52, 1'000,
       (std::int64_t{1} << 52) - (std::int64_t{1} << 51) - 500},
      {"the largest times", std::numeric_limits<std::int64_t>::max() - 2'000, 1'000,
       std::numeric_limits<std::int64_t>::max() - 2'000},
  };
  // Times whose epoch seconds round differently fused (one rounding) and not (two): the kernel
  // must round as the reference does on this machine (found by search; at today's dates the two
  // agree for every nanosecond of a second, close to the epoch they do not).
  std::vector<Point> rounding = random_points(rng, 5, 0, 0);
  const std::int64_t split_times[] = {1'000'027'895, 1'000'040'076, 1'000'095'866, 2'000'055'790,
                                      100'000'067'971};
  for (std::size_t i = 0; i < rounding.size(); ++i)
    rounding[i].timestamp_ns = split_times[i];
  for (const DecoderTarget target : targets) {
    for (const PcdLayout layout : {PcdLayout::kPcl, PcdLayout::kPandarcap}) {
      for (std::size_t i = 0; i < rounding.size(); ++i) {
        require_same_encoding(PcdEncoder(target), std::span(rounding).subspan(i, 1),
                              {layout, Axes::kHesai}, {},
                              "a time fused and unfused rounding tell apart");
      }
    }
  }
  for (const Case& c : cases) {
    const std::vector<Point> points = random_points(rng, 37, c.t0_ns, c.spread_ns);
    for (const DecoderTarget target : targets) {
      const PcdEncoder encoder(target);
      for (const PcdLayout layout : kSimdLayouts) {
        for (const Axes axes : {Axes::kHesai, Axes::kRos}) {
          require_same_encoding(encoder, points, {layout, axes},
                                {c.reference_ns, ReturnMode::kLast}, c.what);
        }
      }
    }
  }
}
