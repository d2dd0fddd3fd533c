// The accessors of a model whose packet is a header, kBlocks alike blocks and a tail (Pandar64,
// the XT protocol): a block is an azimuth at kBlockAzimuthOffset, then kChannels units of
// kUnitBytes from kFirstUnitOffset, each a distance (u16, little-endian) and its reflectivity;
// the tail's fields sit at the model's offsets. A model derives from UniformBlocks<Model> (CRTP)
// and its constants are read where an accessor is used, so each model's code stays its own
// offsets with one set of reads. The QT128's blocks depend on its header's flags: not this.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>

#include "core/sensors/model_facts.hpp"
#include "core/sensors/packet.hpp"

namespace pandarcap {

template <class Model>
struct UniformBlocks {
  using Bytes = std::span<const std::uint8_t>;

  static const std::uint8_t* block(Bytes p, int b) noexcept {
    return p.data() + Model::kHeaderBytes + Model::kBlockBytes * static_cast<std::size_t>(b);
  }
  static const std::uint8_t* unit(Bytes p, int b, int c) noexcept {
    return block(p, b) + Model::kFirstUnitOffset + Model::kUnitBytes * static_cast<std::size_t>(c);
  }
  static std::uint16_t azimuth_cdeg(Bytes p, int b) noexcept {
    return load_u16_le(block(p, b) + Model::kBlockAzimuthOffset);
  }
  // Every block's azimuth below 36000 (the packet's length already checked).
  static bool azimuths_in_range(Bytes p) noexcept {
    for (int b = 0; b < Model::kBlocks; ++b) {
      if (azimuth_cdeg(p, b) >= kAzimuthLimitCdeg) return false;
    }
    return true;
  }
  static std::uint16_t distance_raw(Bytes p, int b, int c) noexcept {
    return load_u16_le(unit(p, b, c));
  }
  static std::uint8_t reflectivity(Bytes p, int b, int c) noexcept { return unit(p, b, c)[2]; }
  static double distance_unit_m(Bytes p) noexcept { return p[Model::kDistanceUnitOffset] * 1e-3; }
  static std::uint16_t motor_rpm(Bytes p) noexcept {
    return load_u16_le(p.data() + Model::kMotorSpeedOffset);
  }
  static std::uint32_t timestamp_us(Bytes p) noexcept {
    return load_u32_le(p.data() + Model::kTimestampOffset);
  }
  static ReturnMode return_mode(Bytes p) noexcept {
    return static_cast<ReturnMode>(p[Model::kReturnModeOffset]);
  }
  static std::uint8_t factory(Bytes p) noexcept { return p[Model::kFactoryOffset]; }
  // The tail's date, its year by the model's rule (Model::year_from_raw).
  static PacketDateTime utc(Bytes p) noexcept {
    const std::uint8_t* t = p.data() + Model::kDateTimeOffset;
    return {Model::year_from_raw(t[0]), t[1], t[2], t[3], t[4], t[5]};
  }
};

}  // namespace pandarcap
