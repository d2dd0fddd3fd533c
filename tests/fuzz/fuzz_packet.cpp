// Fuzz target: one UDP payload through validation and every decoder this CPU runs.
// Invariants: validate() and PacketView agree and never read outside the payload (ASan); a valid
// payload decodes to the same points and filter counts with the scalar reference and every SIMD
// kernel (within the kernels' documented 1e-4 m), for both firing-time settings.
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "core/decode/calibration.hpp"
#include "core/decode/decoder_target.hpp"
#include "core/decode/packet_decoder.hpp"
#include "core/decode/simd_decoder.hpp"
#include "core/sensors/packet.hpp"

using namespace pandarcap;

namespace {

struct Decoders {
  Calibration calibration = Calibration::nominal();
  std::vector<std::unique_ptr<PacketDecoder>> all;  // scalar first
  explicit Decoders(bool firing_time_correction) {
    DecoderConfig config;
    config.firing_time_correction = firing_time_correction;
    for (const DecoderTarget target : supported_decoder_targets())
      all.push_back(std::make_unique<PacketDecoder>(calibration, config, target));
  }
};

// The SIMD kernels' contract with the scalar reference (tests/test_simd_decoder.cpp): the same
// points kept and filtered, the same channel, return type, intensity, time and azimuth label,
// and x, y, z and distance within 1e-4 m (sin/cos by angle addition in float vs double).
bool same_point(const Point& p, const Point& q) {
  constexpr double kToleranceM = 1e-4;
  return q.channel == p.channel && q.return_type == p.return_type && q.intensity == p.intensity &&
         q.timestamp_ns == p.timestamp_ns && q.azimuth_cdeg == p.azimuth_cdeg &&
         std::fabs(q.x - p.x) <= kToleranceM && std::fabs(q.y - p.y) <= kToleranceM &&
         std::fabs(q.z - p.z) <= kToleranceM &&
         std::fabs(q.distance_m - p.distance_m) <= kToleranceM;
}

void check_agree(const Decoders& decoders, const PacketView& packet) {
  constexpr std::int64_t kT0 = 1'700'000'000'000'000'000;
  std::array<Point, kMaxPointsPerPacket> reference{}, points{};
  FilterCounts reference_filtered;
  const DecodedPacket expected = decoders.all[0]->decode(
      packet, kT0, std::span<Point, kMaxPointsPerPacket>(reference), reference_filtered);
  for (std::size_t d = 1; d < decoders.all.size(); ++d) {
    FilterCounts filtered;
    const DecodedPacket got = decoders.all[d]->decode(
        packet, kT0, std::span<Point, kMaxPointsPerPacket>(points), filtered);
    bool same = got.point_count == expected.point_count &&
                got.block_begin == expected.block_begin &&
                filtered.by_reason == reference_filtered.by_reason;
    for (std::size_t i = 0; same && i < expected.point_count; ++i)
      same = same_point(reference[i], points[i]);
    if (!same) {
      std::fprintf(stderr, "fuzz_packet: the %s decoder disagrees with the scalar reference\n",
                   std::string(to_string(decoders.all[d]->target())).c_str());
      std::abort();
    }
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const Decoders plain(false);
  static const Decoders corrected(true);
  const std::span<const std::uint8_t> payload(data, size);
  const RejectReason reason = validate(payload);
  const auto packet = PacketView::make(payload);
  if (packet.has_value() != (reason == RejectReason::kNone)) std::abort();
  if (!packet) return 0;
  (void)packet->tail();
  check_agree(plain, *packet);
  check_agree(corrected, *packet);
  return 0;
}
