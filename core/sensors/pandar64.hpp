// The Pandar64 (Hesai's Pandar64 manual, MAN-64; tier4/nebula's PandarX64 decoder read as the
// reference; /work/research/hesai-models.md §2.2 has every field checked on the real capture).
//
// Layout, 1194 bytes, or 1198 with the UDP sequence:
//
//   offset 0            u8[2]  EE FF (start of packet)
//   offset 2, 3         u8     laser count 64 (0x40), block count 6. There is no protocol version:
//                              read as "major.minor" these would be 64.6 (model_detection.hpp)
//   offset 5            u8     distance unit in mm (4)
//   offset 8 + 194*b    u16    block azimuth, 0.01°. Blocks have no marker.
//   offset 8 + 194*b + 2 + 3*c   u16 distance (× unit), u8 reflectivity
//   offset 1172         the 40P's 22-byte tail: high-temperature flag 1177, motor speed 1180,
//                       µs 1182, return mode 1186, factory 1187, date 1188 (year: see below)
//   offset 1194         u32 UDP sequence (1198-byte packets only)
//
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

struct Pandar64 : FiringRates<55'560, 6>, UniformBlocks<Pandar64> {
  using Blocks = UniformBlocks<Pandar64>;
  static constexpr SensorModelId kId = SensorModelId::kPandar64;
  static constexpr int kChannels = 64;
  static constexpr int kBlocks = 6;
  static constexpr int kMaxPointsPerPacket = kBlocks * kChannels;  // 384

  static constexpr std::size_t kHeaderBytes = 8;
  static constexpr std::size_t kLaserCountOffset = 2;
  static constexpr std::size_t kBlockCountOffset = 3;
  static constexpr std::size_t kDistanceUnitOffset = 5;
  static constexpr std::size_t kUnitBytes = 3;
  static constexpr std::size_t kBlockBytes = 2 + kUnitBytes * kChannels;  // 194
  static constexpr std::size_t kBlockAzimuthOffset = 0;                   // inside a block
  static constexpr std::size_t kFirstUnitOffset = 2;                      // inside a block
  static constexpr std::size_t kTailOffset = kHeaderBytes + kBlocks * kBlockBytes;  // 1172
  static constexpr std::size_t kHighTemperatureOffset = kTailOffset + 5;            // 1177
  static constexpr std::size_t kMotorSpeedOffset = kTailOffset + 8;                 // 1180
  static constexpr std::size_t kTimestampOffset = kTailOffset + 10;                 // 1182
  static constexpr std::size_t kReturnModeOffset = kTailOffset + 14;                // 1186
  static constexpr std::size_t kFactoryOffset = kTailOffset + 15;                   // 1187
  static constexpr std::size_t kDateTimeOffset = kTailOffset + 16;                  // 1188
  static constexpr std::size_t kSequenceOffset = kTailOffset + 22;                  // 1194
  static constexpr std::array<std::size_t, 2> kDatagramBytes = {kSequenceOffset,
                                                                kSequenceOffset + 4};
  static constexpr std::size_t kMaxDatagramBytes = kSequenceOffset + 4;  // 1198

  // The sensor's own range (nebula's Pandar64: 0.3-200 m).
  static constexpr double kMinRangeM = 0.3;
  static constexpr double kMaxRangeM = 200.0;
  // Spin rate options of its web page (MAN-64 §4.2.2): 600 (default) and 1200 RPM.
  static constexpr std::array<int, 2> kSupportedRpms = {600, 1200};
  // MAN-64 §4.2.2: single return last or strongest, dual last + strongest (nebula: the same).
  static constexpr std::array<ReturnMode, 3> kReturnModes = {ReturnMode::kStrongest,
                                                             ReturnMode::kLast, ReturnMode::kDual};

  // The nominal table: no design table of the Pandar64 manual was at hand, so this is the table
  // Hesai's own General SDK uses for a Pandar64 without a calibration file
  // (HesaiLidar_General_SDK, src/PandarGeneralRaw/src/pandarGeneral_internal.cc,
  // pandarGeneral_elev_angle_map and pandarGeneral_horizatal_azimuth_offset_map). Its azimuth
  // offsets are the design's (±1.042, ±3.125, ±5.208°); its elevations lie within 0.07° of the
  // design's 1/6° grid (channels 7-54) and within 0.15° of the real capture's unit.
  static constexpr std::array<double, kChannels> kNominalElevationDeg = {
      14.882, 11.032, 8.059,  5.057,   3.04,    2.028,   1.86,   1.688,   1.522,  1.351,  1.184,
      1.013,  0.846,  0.675,  0.508,   0.337,   0.169,   0.0,    -0.169,  -0.337, -0.508, -0.675,
      -0.845, -1.013, -1.184, -1.351,  -1.522,  -1.688,  -1.86,  -2.028,  -2.198, -2.365, -2.536,
      -2.7,   -2.873, -3.04,  -3.21,   -3.375,  -3.548,  -3.712, -3.884,  -4.05,  -4.221, -4.385,
      -4.558, -4.72,  -4.892, -5.057,  -5.229,  -5.391,  -5.565, -5.726,  -5.898, -6.061, -7.063,
      -8.059, -9.06,  -9.885, -11.032, -12.006, -12.974, -13.93, -18.889, -24.897};
  static constexpr std::array<double, kChannels> kNominalAzimuthOffsetDeg = {
      -1.042, -1.042, -1.042, -1.042, -1.042, -1.042, 1.042,  3.125,  5.208,  -5.208, -3.125,
      -1.042, 1.042,  3.125,  5.208,  -5.208, -3.125, -1.042, 1.042,  3.125,  5.208,  -5.208,
      -3.125, -1.042, 1.042,  3.125,  5.208,  -5.208, -3.125, -1.042, 1.042,  3.125,  5.208,
      -5.208, -3.125, -1.042, 1.042,  3.125,  5.208,  -5.208, -3.125, -1.042, 1.042,  3.125,
      5.208,  -5.208, -3.125, -1.042, 1.042,  3.125,  5.208,  -5.208, -3.125, -1.042, -1.042,
      -1.042, -1.042, -1.042, -1.042, -1.042, -1.042, -1.042, -1.042, -1.042};

  // Firing times (ns) of each channel inside its firing round, added to the block's offset
  // (negative: earlier). nebula's Pandar64 table, equal to the General SDK's laser64Offset_
  // (1.304 µs and 1.968 µs steps from 3.62 µs), negated.
  static constexpr std::array<std::int32_t, kChannels> kChannelOffsetNs = {
      -23180, -21876, -20572, -19268, -17964, -16660, -11444, -46796,  //  1..8
      -7532,  -36956, -50732, -54668, -40892, -44828, -31052, -34988,  //  9..16
      -48764, -52700, -38924, -42860, -29084, -33020, -46796, -25148,  // 17..24
      -36956, -50732, -27116, -40892, -44828, -31052, -34988, -48764,  // 25..32
      -25148, -38924, -42860, -29084, -33020, -52700, -6228,  -54668,  // 33..40
      -15356, -27116, -10140, -23180, -4924,  -21876, -14052, -17964,  // 41..48
      -8836,  -19268, -3620,  -20572, -12748, -16660, -7532,  -11444,  // 49..56
      -6228,  -15356, -10140, -4924,  -3620,  -14052, -8836,  -12748,  // 57..64
  };
  // The last firing round ends this long before the packet's time.
  static constexpr std::int64_t kLastRoundEndNs = 42'580;

  // EE FF; laser count 64 and block count 6 (else wrong_model); 1194 or 1198 bytes; azimuths
  // < 36000; a return mode of kReturnModes. The distance unit byte is not checked: 0 makes every
  // distance 0, which the range filter counts.
  static RejectReason validate(std::span<const std::uint8_t> p) noexcept {
    if (p.size() < kHeaderBytes) return RejectReason::kBadLength;
    if (p[0] != 0xEE || p[1] != 0xFF) return RejectReason::kBadMarker;
    if (p[kLaserCountOffset] != kChannels || p[kBlockCountOffset] != kBlocks) {
      return RejectReason::kWrongModel;
    }
    if (p.size() != kDatagramBytes[0] && p.size() != kDatagramBytes[1]) {
      return RejectReason::kBadLength;
    }
    if (!Blocks::azimuths_in_range(p)) return RejectReason::kBadAzimuth;
    const auto mode = return_mode_from_byte(p[kReturnModeOffset]);
    if (!mode || !mode_listed(kReturnModes, *mode)) return RejectReason::kBadReturnMode;
    return RejectReason::kNone;
  }

  static bool high_temperature(std::span<const std::uint8_t> p) noexcept {
    return p[kHighTemperatureOffset] != 0;
  }
  static std::optional<std::uint32_t> sequence(std::span<const std::uint8_t> p) noexcept {
    if (p.size() < kMaxDatagramBytes) return std::nullopt;
    return load_u32_le(p.data() + kSequenceOffset);
  }
  // Hesai's SDK rule: raw < 70 counts from 2000, else from 1900 (the capture's raw 120 = 2020).
  // nebula reads the 40P's tail here, year 2000 + raw, and dates this capture 2120: a bug; its
  // timestamps for the 64 are 100 years ahead of these.
  static constexpr std::uint16_t year_from_raw(std::uint8_t raw) noexcept {
    return static_cast<std::uint16_t>(raw < 70 ? 2000 + raw : 1900 + raw);
  }

  // When channel `channel` of block `block` fired, relative to the packet's time (ns; negative:
  // before it). Firing rounds are 55.56 µs apart, the last ends 42.58 µs before the packet time,
  // and the blocks of one firing (`returns` of them) share its round.
  static constexpr std::int64_t firing_offset_ns(int block, int channel, int returns) noexcept {
    return -kLastRoundEndNs - kFiringPeriodNs * ((kBlocks - 1 - block) / returns) +
           kChannelOffsetNs[static_cast<std::size_t>(channel)];
  }
  static std::int64_t firing_offset_ns(std::span<const std::uint8_t>, int block, int channel,
                                       int returns) noexcept {
    return firing_offset_ns(block, channel, returns);
  }
};

}  // namespace pandarcap
