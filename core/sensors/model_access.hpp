// What the stream rules need of a model beyond its accessors, in one place: where a packet's
// return-mode byte and block azimuths sit (the stream decoder mends a glitched mode byte and a
// shifted azimuth in a copy of the packet), and its date in the packet clock's terms.
//
// The 40P's offsets are its packet.hpp's; the Pandar64 and the XT protocol place blocks after a
// header at fixed offsets (UniformBlocks); the QT128's follow its flags byte (layout(p)).
#pragma once

#include <concepts>
#include <cstddef>
#include <cstdint>
#include <span>

#include "core/sensors/model_facts.hpp"
#include "core/sensors/packet.hpp"
#include "core/sensors/pandar40p.hpp"
#include "core/sensors/pandar_qt128.hpp"

namespace pandarcap {

// Offset of the tail's return-mode byte in a packet the model's validate() accepted.
template <class Model>
std::size_t return_mode_offset(std::span<const std::uint8_t> p) noexcept {
  if constexpr (std::same_as<Model, PandarQT128>) {
    return PandarQT128::layout(p).tail_offset + PandarQT128::kReturnModeInTail;
  } else {
    return Model::kReturnModeOffset;
  }
}

// Offset of block `b`'s azimuth (u16, little-endian) in a packet the model's validate() accepted.
template <class Model>
std::size_t block_azimuth_offset(std::span<const std::uint8_t> p, int b) noexcept {
  const auto block = static_cast<std::size_t>(b);
  if constexpr (std::same_as<Model, PandarQT128>) {
    return PandarQT128::kHeaderBytes + PandarQT128::layout(p).block_bytes * block +
           PandarQT128::kBlockAzimuthOffset;
  } else {
    return Model::kHeaderBytes + Model::kBlockBytes * block + Model::kBlockAzimuthOffset;
  }
}

// The tail's date as the packet clock takes it (years 2000-2255). A model whose year rule gives
// an earlier year (a clock that counts from 1900 and was never set: 1970) gets month 0, so the
// clock calls it a bad date rather than a time 30 years off.
constexpr TailDateTime to_tail_datetime(const PacketDateTime& d) noexcept {
  TailDateTime t{0, d.month, d.day, d.hour, d.minute, d.second};
  if (d.year < 2000 || d.year > 2255) {
    t.month = 0;
  } else {
    t.year_since_2000 = static_cast<std::uint8_t>(d.year - 2000);
  }
  return t;
}

// The packet's tail date: the 40P's own view (unchanged bytes in, unchanged time out), the
// others' through their year rule.
template <class Model>
TailDateTime tail_datetime(std::span<const std::uint8_t> p) noexcept {
  if constexpr (std::same_as<Model, Pandar40P>) {
    return PacketView::assume_valid(p).utc();
  } else {
    return to_tail_datetime(Model::utc(p));
  }
}

}  // namespace pandarcap
