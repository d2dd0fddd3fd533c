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
#include <optional>
#include <span>

#include "core/sensors/model_facts.hpp"
#include "core/sensors/packet.hpp"
#include "core/sensors/pandar40p.hpp"
#include "core/sensors/pandar_qt128.hpp"
#include "core/sensors/pandar_xt.hpp"

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

// The run of bytes at a packet's end that a sensor's clock rewrites from one packet to the next
// (a traffic generator writes them per packet, the body before them being a loop's): where the
// µs and the date are in it, the year's base, the UDP sequence when it is inside the run (the
// 40P's and the Pandar64's is appended after it), and a CRC over the run's bytes before it.
struct TimeRun {
  static constexpr std::size_t kMaxBytes = 40;
  std::size_t offset = 0;  // in the packet
  std::size_t bytes = 0;   // offset + bytes = the packet's size without an appended sequence
  std::size_t micros_at = 0;
  std::size_t date_at = 0;  // year, month, day, hour, minute, second
  int year_base = 2000;     // what the year byte counts from
  std::optional<std::size_t> sequence_at;
  std::optional<std::size_t> crc_at;  // u32 CRC-32/MPEG-2 of the run's bytes before it
};

template <class Model>
TimeRun time_run(std::span<const std::uint8_t> p) noexcept {
  TimeRun t;
  if constexpr (std::same_as<Model, PandarQT128>) {
    // The tail, the sequence when flagged, the CRC over both (no signature written).
    const PandarQT128::Layout l = PandarQT128::layout(p);
    t.offset = l.tail_offset;
    t.bytes = l.tail_crc_offset + PandarQT128::kCrcBytes - l.tail_offset;
    t.micros_at = PandarQT128::kTimestampInTail;
    t.date_at = PandarQT128::kDateTimeInTail;
    t.year_base = 1900;
    if (l.sequence_offset) t.sequence_at = *l.sequence_offset - l.tail_offset;
    t.crc_at = l.tail_crc_offset - l.tail_offset;
  } else if constexpr (std::same_as<Model, PandarXT32> || std::same_as<Model, PandarXT16>) {
    // Date, µs, factory, sequence: the datagram's last 15 bytes.
    t.offset = Model::kDateTimeOffset;
    t.bytes = Model::kSequenceOffset + 4 - Model::kDateTimeOffset;
    t.micros_at = Model::kTimestampOffset - Model::kDateTimeOffset;
    t.date_at = 0;
    t.year_base = 1900;
    t.sequence_at = Model::kSequenceOffset - Model::kDateTimeOffset;
  } else {
    // The 40P's tail (the Pandar64's too): µs, return mode, factory, date; the sequence after.
    (void)p;
    t.offset = Model::kTimestampOffset;
    t.bytes = Model::kDateTimeOffset + 6 - Model::kTimestampOffset;
    t.micros_at = 0;
    t.date_at = Model::kDateTimeOffset - Model::kTimestampOffset;
    t.year_base = 2000;
  }
  return t;
}

// Whether the model's UDP sequence is a flag of its header (the QT128's) rather than a datagram
// length (the 40P's, the Pandar64's) or always there (the XT's).
template <class Model>
inline constexpr bool kSequenceFlagged = std::same_as<Model, PandarQT128>;

// Rewrites the checksums a packet carries after its bytes were changed (the QT128's CRCs; the
// others carry none).
template <class Model>
void write_checksums(std::span<std::uint8_t> p) noexcept {
  if constexpr (std::same_as<Model, PandarQT128>) {
    PandarQT128::write_crcs(p);
  } else {
    (void)p;
  }
}

}  // namespace pandarcap
