// The Pandar40P as a model type: a thin layer over packet.hpp (its layout, validate() and
// PacketView) and timing.hpp (its firing times), which stay the 40P's own and tuned (the 40-lane
// SIMD kernels read them), so nothing the 40P outputs changes. The sibling headers
// (pandar64.hpp, pandar_xt.hpp, pandar_qt128.hpp) have the same members.
//
// Layout (spec §1, ../shared/spec/pandar40p-protocol.md): no header; 10 blocks of 124 bytes
// (marker FF EE, azimuth u16, 40 × {distance u16, reflectivity u8}), a 22-byte tail, and a u32
// UDP sequence when the sensor's option is on: 1262 or 1266 bytes. Distances in 4 mm, fixed.
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
#include "core/sensors/timing.hpp"

namespace pandarcap {

struct Pandar40P : FiringRates<kRoundPeriodNs, kBlocks> {
  static constexpr SensorModelId kId = SensorModelId::kPandar40P;
  static constexpr int kChannels = pandarcap::kChannels;  // 40
  static constexpr int kBlocks = pandarcap::kBlocks;      // 10
  static constexpr int kMaxPointsPerPacket = kBlocks * kChannels;

  // Layout: every offset from the payload's first byte.
  static constexpr std::array<std::size_t, 2> kDatagramBytes = {kPacketBytes,
                                                                kPacketWithSequenceBytes};
  static constexpr std::size_t kMaxDatagramBytes = kMaxPacketBytes;  // 1266
  static constexpr std::size_t kHeaderBytes = 0;
  static constexpr std::size_t kBlockBytes = pandarcap::kBlockBytes;      // 124, marker included
  static constexpr std::size_t kBlockAzimuthOffset = 2;                   // inside a block
  static constexpr std::size_t kFirstUnitOffset = 4;                      // inside a block
  static constexpr std::size_t kUnitBytes = 3;                            // distance u16, refl. u8
  static constexpr std::size_t kTailOffset = kBodyBytes;                  // 1240
  static constexpr std::size_t kHighTemperatureOffset = kTailOffset + 5;  // 1245
  static constexpr std::size_t kMotorSpeedOffset = kTailOffset + 8;       // 1248
  static constexpr std::size_t kTimestampOffset = kTailOffset + 10;       // 1250
  static constexpr std::size_t kReturnModeOffset = kTailOffset + 14;      // 1254
  static constexpr std::size_t kFactoryOffset = kTailOffset + 15;         // 1255
  static constexpr std::size_t kDateTimeOffset = kTailOffset + 16;        // 1256
  static constexpr std::size_t kSequenceOffset = kPacketBytes;            // 1262, if present

  static constexpr double kDistanceUnitM = pandarcap::kDistanceUnitM;  // 4 mm, no header byte
  // The sensor's own range (nebula's Pandar40P: 0.3-200 m), today's configured default too.
  static constexpr double kMinRangeM = 0.3;
  static constexpr double kMaxRangeM = 200.0;
  // The speeds the sensor is set to (SPEC40 §6: 600 and 1200 RPM evidenced on real units).
  static constexpr std::array<int, 2> kSupportedRpms = {600, 1200};
  static constexpr std::array<ReturnMode, 3> kReturnModes = kPandar40PReturnModes;

  // The nominal (design) table, used without a calibration file: MAN40 Appendix I, the same as
  // Hesai's General SDK default (pandarGeneral_internal.cc, pandar40p_elev_angle_map). The SDK
  // has -1.66° for channel 17; every neighbouring step is 1/3°, so the design value -1.67 is
  // used. Per-unit files differ from it by up to ~0.45° in elevation.
  static constexpr std::array<double, kChannels> kNominalElevationDeg = {
      15.0, 11.0,  8.0,   5.0,   3.0,   2.0,   1.67,  1.33,  1.0,   0.67,
      0.33, 0.0,   -0.33, -0.67, -1.0,  -1.33, -1.67, -2.0,  -2.33, -2.67,
      -3.0, -3.33, -3.67, -4.0,  -4.33, -4.67, -5.0,  -5.33, -5.67, -6.0,
      -7.0, -8.0,  -9.0,  -10.0, -11.0, -12.0, -13.0, -14.0, -19.0, -25.0};
  // Channels 1-6 and 31-40 at -1.042°; channels 7-30 cycle +3.125, -5.208, -1.042 (MAN40).
  static constexpr std::array<double, kChannels> kNominalAzimuthOffsetDeg = {
      -1.042, -1.042, -1.042, -1.042, -1.042, -1.042, 3.125,  -5.208, -1.042, 3.125,
      -5.208, -1.042, 3.125,  -5.208, -1.042, 3.125,  -5.208, -1.042, 3.125,  -5.208,
      -1.042, 3.125,  -5.208, -1.042, 3.125,  -5.208, -1.042, 3.125,  -5.208, -1.042,
      -1.042, -1.042, -1.042, -1.042, -1.042, -1.042, -1.042, -1.042, -1.042, -1.042};

  // Length (1262 or 1266), the ten FF EE markers, azimuths < 36000, return mode 0x37-0x39.
  static RejectReason validate(std::span<const std::uint8_t> p) noexcept {
    return pandarcap::validate(p);
  }
  static PacketView view(std::span<const std::uint8_t> p) noexcept {
    return PacketView::assume_valid(p);
  }
  static std::uint16_t azimuth_cdeg(std::span<const std::uint8_t> p, int block) noexcept {
    return view(p).azimuth_cdeg(block);
  }
  static std::uint16_t distance_raw(std::span<const std::uint8_t> p, int block,
                                    int channel) noexcept {
    return view(p).distance_raw(block, channel);
  }
  static std::uint8_t reflectivity(std::span<const std::uint8_t> p, int block,
                                   int channel) noexcept {
    return view(p).reflectivity(block, channel);
  }
  static double distance_unit_m(std::span<const std::uint8_t>) noexcept { return kDistanceUnitM; }
  static std::uint16_t motor_rpm(std::span<const std::uint8_t> p) noexcept {
    return view(p).motor_rpm();
  }
  static std::uint32_t timestamp_us(std::span<const std::uint8_t> p) noexcept {
    return view(p).timestamp_us();
  }
  static ReturnMode return_mode(std::span<const std::uint8_t> p) noexcept {
    return view(p).return_mode();
  }
  static std::uint8_t factory(std::span<const std::uint8_t> p) noexcept {
    return p[kFactoryOffset];
  }
  static bool high_temperature(std::span<const std::uint8_t> p) noexcept {
    return p[kHighTemperatureOffset] != 0;
  }
  static std::optional<std::uint32_t> sequence(std::span<const std::uint8_t> p) noexcept {
    return view(p).sequence();
  }
  // The tail's year byte counts from 2000 (MAN40P; raw 17 = 2017).
  static constexpr std::uint16_t year_from_raw(std::uint8_t raw) noexcept {
    return static_cast<std::uint16_t>(2000 + raw);
  }
  static PacketDateTime utc(std::span<const std::uint8_t> p) noexcept {
    const TailDateTime t = view(p).utc();
    return {year_from_raw(t.year_since_2000), t.month, t.day, t.hour, t.minute, t.second};
  }

  // When channel `channel` of block `block` fired, relative to the packet's time (ns; negative:
  // before it): timing.hpp's block offset minus the channel's Δt (spec §2). `returns` is 1 or 2.
  static constexpr std::int64_t firing_offset_ns(int block, int channel, int returns) noexcept {
    return block_offset_ns(block, returns == 2 ? ReturnMode::kDual : ReturnMode::kLast) -
           kChannelFiringOffsetNs[static_cast<std::size_t>(channel)];
  }
  static std::int64_t firing_offset_ns(std::span<const std::uint8_t>, int block, int channel,
                                       int returns) noexcept {
    return firing_offset_ns(block, channel, returns);
  }
};

}  // namespace pandarcap
