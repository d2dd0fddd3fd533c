// The PandarXT32 and PandarXT16: one protocol (6.1, the PandarXT manual MAN-XT; nebula's
// PandarXT32/PandarXT16 decoders read as the reference; /work/research/hesai-models.md §2.3 has
// every field checked on the real XT32 capture and nebula's XT16 test bag), one template over the
// channel count, which the header's laser-count byte must match.
//
// Layout (N channels; XT32: 1080 bytes, XT16: 568; the UDP sequence is always there):
//
//   offset 0         u8[2]  EE FF;  2, 3: protocol 6.1;  6: laser count N;  7: block count 8;
//                    9: distance unit in mm (4);  11: flags (0x01: UDP sequence, always set)
//   offset 12 + (2 + 4N)*b          u16 block azimuth, 0.01°
//   offset 12 + (2 + 4N)*b + 2 + 4c  u16 distance (× unit), u8 reflectivity, u8 confidence
//   tail T = 12 + 8(2 + 4N) (1052 / 540): reserved 9, high temperature T+9, return mode T+10,
//   motor speed T+11, date T+13 (year from 1900), µs T+19, factory T+23, sequence T+24
//
// There is no CRC. The XT32 capture's dual pairs hold the nearer echo in the even block, against
// its header and the manual (hesai-models.md §2.7): it changes labels, not points.
// Accessors take the payload bytes and are valid only on a payload validate() accepted.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>

#include "core/sensors/model_facts.hpp"
#include "core/sensors/packet.hpp"
#include "core/sensors/sensor_model_id.hpp"
#include "core/sensors/uniform_blocks.hpp"

namespace pandarcap {

namespace xt_design {

// PandarXT32: Hesai's General SDK default for the XT (HesaiLidar_General_SDK, pandarXT.h,
// pandarXT_elev_angle_map / pandarXT_horizatal_azimuth_offset_map): 15° to -16° in 1° steps, no
// azimuth offset, the design the PandarXT manual's Appendix I states (its values "are design
// values"; the unit's own are in its calibration file).
inline constexpr std::array<double, 32> kXt32ElevationDeg = {
    15.0, 14.0, 13.0, 12.0,  11.0,  10.0,  9.0,   8.0,   7.0,   6.0,  5.0,
    4.0,  3.0,  2.0,  1.0,   0.0,   -1.0,  -2.0,  -3.0,  -4.0,  -5.0, -6.0,
    -7.0, -8.0, -9.0, -10.0, -11.0, -12.0, -13.0, -14.0, -15.0, -16.0};
// PandarXT-16: the manual's Appendix I design table (MAN-XT16 p.66): 15° to -15° in 2° steps,
// no azimuth offset. nebula's calibration/PandarXT16.csv holds the same values.
inline constexpr std::array<double, 16> kXt16ElevationDeg = {
    15.0, 13.0, 11.0, 9.0, 7.0, 5.0, 3.0, 1.0, -1.0, -3.0, -5.0, -7.0, -9.0, -11.0, -13.0, -15.0};

}  // namespace xt_design

template <int N>
struct PandarXT : FiringRates<50'000, 8>, UniformBlocks<PandarXT<N>> {
  using Blocks = UniformBlocks<PandarXT>;
  static_assert(N == 32 || N == 16, "the XT protocol's models have 32 or 16 channels");
  static constexpr SensorModelId kId =
      N == 32 ? SensorModelId::kPandarXT32 : SensorModelId::kPandarXT16;
  static constexpr int kChannels = N;
  static constexpr int kBlocks = 8;
  static constexpr int kMaxPointsPerPacket = kBlocks * kChannels;  // 256 / 128

  static constexpr std::uint8_t kProtocolMajor = 6;
  static constexpr std::uint8_t kProtocolMinor = 1;
  static constexpr std::size_t kHeaderBytes = 12;
  static constexpr std::size_t kLaserCountOffset = 6;
  static constexpr std::size_t kBlockCountOffset = 7;
  static constexpr std::size_t kDistanceUnitOffset = 9;
  static constexpr std::size_t kFlagsOffset = 11;
  static constexpr std::size_t kUnitBytes = 4;
  static constexpr std::size_t kBlockBytes = 2 + kUnitBytes * N;  // 130 / 66
  static constexpr std::size_t kBlockAzimuthOffset = 0;           // inside a block
  static constexpr std::size_t kFirstUnitOffset = 2;              // inside a block
  static constexpr std::size_t kTailOffset = kHeaderBytes + kBlocks * kBlockBytes;  // 1052 / 540
  static constexpr std::size_t kHighTemperatureOffset = kTailOffset + 9;
  static constexpr std::size_t kReturnModeOffset = kTailOffset + 10;
  static constexpr std::size_t kMotorSpeedOffset = kTailOffset + 11;
  static constexpr std::size_t kDateTimeOffset = kTailOffset + 13;
  static constexpr std::size_t kTimestampOffset = kTailOffset + 19;
  static constexpr std::size_t kFactoryOffset = kTailOffset + 23;
  static constexpr std::size_t kSequenceOffset = kTailOffset + 24;
  static constexpr std::array<std::size_t, 1> kDatagramBytes = {kSequenceOffset + 4};  // 1080/568
  static constexpr std::size_t kMaxDatagramBytes = kDatagramBytes[0];

  // The sensor's own range (nebula's XT32 and XT16: 0.05-120 m).
  static constexpr double kMinRangeM = 0.05;
  static constexpr double kMaxRangeM = 120.0;
  // Spin rate options (MAN-XT16 §4.2.2: 600 and 1200 RPM); the XT32 is taken to offer the same
  // (its manual's settings page was not at hand).
  static constexpr std::array<int, 2> kSupportedRpms = {600, 1200};
  // MAN-XT16 §3.1.2: single first, strongest, last; dual last + strongest, last + first,
  // first + strongest (nebula allows the same for both XTs).
  static constexpr std::array<ReturnMode, 6> kReturnModes = {
      ReturnMode::kFirst, ReturnMode::kStrongest, ReturnMode::kLast,
      ReturnMode::kDual,  ReturnMode::kFirstLast, ReturnMode::kFirstStrongest};

  static constexpr std::array<double, N> kNominalElevationDeg = [] {
    if constexpr (N == 32) {
      return xt_design::kXt32ElevationDeg;
    } else {
      return xt_design::kXt16ElevationDeg;
    }
  }();
  static constexpr std::array<double, N> kNominalAzimuthOffsetDeg{};  // all 0

  // Firing times (nebula's XT decoders; the General SDK's blockXTOffset and laserXTOffset, in
  // µs): a firing every 50 µs, the packet's last firing 5.632 µs after the packet time, the
  // ones before it 50 µs earlier each; inside a firing channel c at 0.368 µs + c × 1.512 µs
  // (XT32) or c × 3.024 µs (XT16).
  static constexpr std::int64_t kLastBlockOffsetNs = 5'632;
  static constexpr std::int64_t kFirstChannelNs = 368;
  static constexpr std::int64_t kChannelStepNs = N == 32 ? 1'512 : 3'024;

  // EE FF; protocol 6.1, laser count N, block count 8 (else wrong_model); the model's length;
  // azimuths < 36000; a return mode of kReturnModes.
  static RejectReason validate(std::span<const std::uint8_t> p) noexcept {
    if (p.size() < kHeaderBytes) return RejectReason::kBadLength;
    if (p[0] != 0xEE || p[1] != 0xFF) return RejectReason::kBadMarker;
    if (p[2] != kProtocolMajor || p[3] != kProtocolMinor || p[kLaserCountOffset] != N ||
        p[kBlockCountOffset] != kBlocks) {
      return RejectReason::kWrongModel;
    }
    if (p.size() != kMaxDatagramBytes) return RejectReason::kBadLength;
    if (!Blocks::azimuths_in_range(p)) return RejectReason::kBadAzimuth;
    const auto mode = return_mode_from_byte(p[kReturnModeOffset]);
    if (!mode || !mode_listed(kReturnModes, *mode)) return RejectReason::kBadReturnMode;
    return RejectReason::kNone;
  }

  static std::uint8_t confidence(std::span<const std::uint8_t> p, int b, int c) noexcept {
    return Blocks::unit(p, b, c)[3];
  }
  // Bit 0 of the shutdown flag (MAN-XT: 0x01 high temperature, shutting down in 60 s).
  static bool high_temperature(std::span<const std::uint8_t> p) noexcept {
    return (p[kHighTemperatureOffset] & 0x01) != 0;
  }
  static std::optional<std::uint32_t> sequence(std::span<const std::uint8_t> p) noexcept {
    return load_u32_le(p.data() + kSequenceOffset);
  }
  // MAN-XT: "current year minus 1900" (the XT32 capture's raw 119 = 2019). A year byte of 0
  // (the SDK's alternative: Unix seconds in the date's last four bytes) is not read as such.
  static constexpr std::uint16_t year_from_raw(std::uint8_t raw) noexcept {
    return static_cast<std::uint16_t>(1900 + raw);
  }

  // When channel `channel` of block `block` fired, relative to the packet's time (ns). The
  // blocks of one firing (`returns` of them: 1 or 2) share its time.
  static constexpr std::int64_t firing_offset_ns(int block, int channel, int returns) noexcept {
    return kLastBlockOffsetNs - kFiringPeriodNs * ((kBlocks - 1 - block) / returns) +
           kFirstChannelNs + kChannelStepNs * channel;
  }
  static std::int64_t firing_offset_ns(std::span<const std::uint8_t>, int block, int channel,
                                       int returns) noexcept {
    return firing_offset_ns(block, channel, returns);
  }
};

using PandarXT32 = PandarXT<32>;
using PandarXT16 = PandarXT<16>;

}  // namespace pandarcap
