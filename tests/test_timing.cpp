// Block and channel firing offsets against the spec's tables (§2.2, §2.3).
#include <catch2/catch.hpp>

#include "core/sensors/timing.hpp"

using namespace pandarcap;

TEST_CASE("single-return block offsets match the spec table", "[timing]") {
  // Spec §2.2, µs relative to t0, 0-based blocks.
  const double expected_us[kBlocks] = {-528.62, -473.06, -417.50, -361.94, -306.38,
                                       -250.82, -195.26, -139.70, -84.14,  -28.58};
  for (int b = 0; b < kBlocks; ++b) {
    CHECK(block_offset_ns(b, ReturnMode::kStrongest) == std::llround(expected_us[b] * 1000));
    CHECK(block_offset_ns(b, ReturnMode::kLast) == std::llround(expected_us[b] * 1000));
  }
}

TEST_CASE("dual-return block offsets pair blocks and match the spec table", "[timing]") {
  const double expected_us[kBlocks] = {-250.82, -250.82, -195.26, -195.26, -139.70,
                                       -139.70, -84.14,  -84.14,  -28.58,  -28.58};
  for (int b = 0; b < kBlocks; ++b) {
    CHECK(block_offset_ns(b, ReturnMode::kDual) == std::llround(expected_us[b] * 1000));
  }
}

TEST_CASE("channel firing offsets match the manual's firing-sequence table", "[timing]") {
  // Spec §2.3, second table: sequence index -> (1-based channel, Δt µs).
  const struct {
    int channel;
    double dt_us;
  } sequence[kChannels] = {
      {4, 3.62},   {40, 3.62},  {36, 4.92},  {28, 6.23},  {12, 8.19},  {16, 8.19},  {32, 9.50},
      {24, 11.47}, {29, 12.77}, {17, 14.74}, {3, 16.04},  {39, 16.04}, {35, 17.35}, {25, 18.65},
      {9, 20.62},  {13, 20.62}, {31, 21.92}, {21, 23.89}, {26, 25.19}, {14, 27.16}, {2, 28.47},
      {38, 28.47}, {34, 29.77}, {6, 31.74},  {22, 31.74}, {10, 33.71}, {30, 35.01}, {18, 36.98},
      {23, 38.95}, {11, 40.91}, {1, 42.22},  {37, 42.22}, {33, 43.52}, {5, 45.49},  {19, 45.49},
      {7, 47.46},  {27, 48.76}, {15, 50.73}, {20, 52.70}, {8, 54.67}};
  std::array<int, kChannels> seen{};
  for (const auto& entry : sequence) {
    INFO("channel " << entry.channel);
    CHECK(kChannelFiringOffsetNs[entry.channel - 1] == std::llround(entry.dt_us * 1000));
    ++seen[entry.channel - 1];
  }
  for (int count : seen)
    CHECK(count == 1);
}

TEST_CASE("packet periods follow the 55.56 µs firing round", "[timing]") {
  CHECK(packet_period_ns(ReturnMode::kStrongest) == 555'600);  // 1800 packets/s
  CHECK(packet_period_ns(ReturnMode::kDual) == 277'800);       // 3600 packets/s
  CHECK(rounds_per_packet(ReturnMode::kLast) == 10);
  CHECK(rounds_per_packet(ReturnMode::kDual) == 5);
}
