// The simulated models' packets (model_sensor.hpp): one loop over the firings for every model,
// the header, unit and tail bytes placed at each model's offsets.
#include "core/sim/model_sensor.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <type_traits>

#include "core/decode/packet_time.hpp"
#include "core/sim/room_scene.hpp"

namespace pandarcap {

namespace {

constexpr double kUnitM = 0.004;  // every simulated model reports 4 mm units (its header: 4)
constexpr std::uint8_t kUnitMm = 4;
constexpr std::uint8_t kFactory = 0x42;
constexpr std::uint8_t kXtConfidence = 255;  // what both XT captures carry in every unit

template <class M>
constexpr bool kIsQt128 = std::is_same_v<M, PandarQT128>;
template <class M>
constexpr bool kIsXt = std::is_same_v<M, PandarXT32> || std::is_same_v<M, PandarXT16>;

void put_u16(std::uint8_t* p, std::uint16_t v) {
  p[0] = static_cast<std::uint8_t>(v);
  p[1] = static_cast<std::uint8_t>(v >> 8);
}

void put_u32(std::uint8_t* p, std::uint32_t v) {
  for (int i = 0; i < 4; ++i)
    p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}

// The QT128's flags: functional safety and confidence as the real capture has them, the sequence
// as configured; no signature (the capture's is all zero and nothing checks it).
std::uint8_t qt128_flags(bool udp_sequence) {
  return static_cast<std::uint8_t>(PandarQT128::kFlagFunctionalSafety |
                                   PandarQT128::kFlagConfidence |
                                   (udp_sequence ? PandarQT128::kFlagSequence : 0));
}

// Which echo the `echo`-th block of a firing reports: the mode's echoes in the order its name
// gives them (0x39: last, then strongest; hesai-models.md §2.7), except that the XTs send 0x3B's
// last echo first (§5.4: nebula flips the XTs' labels for it alone).
RoomEcho pick(const RoomEchoes& e, ReturnMode mode, int echo, bool last_first) {
  switch (mode) {
    case ReturnMode::kFirst:
      return e.first();
    case ReturnMode::kStrongest:
      return e.strongest;
    case ReturnMode::kDual:
      return echo == 0 ? e.last : e.strongest;
    case ReturnMode::kFirstLast:
      return (echo == 0) != last_first ? e.first() : e.last;
    case ReturnMode::kFirstStrongest:
      return echo == 0 ? e.first() : e.strongest;
    default:  // kLast, the only other mode a simulated model has
      return e.last;
  }
}

// The header's "first block return" byte (hesai-models.md §1.1): 0 single return (or a first
// echo first), 1 the first block is the last return, 2 the strongest.
std::uint8_t first_block_echo(ReturnMode mode, bool last_first) {
  if (returns_per_firing(mode) == 1) return 0;
  if (mode == ReturnMode::kDual || (mode == ReturnMode::kFirstLast && last_first)) return 1;
  return 0;
}

// The year byte the model's year_from_raw() reads as `year` (the inverse of its rule).
template <class M>
std::uint8_t raw_year(int year) {
  for (int raw = 0; raw < 256; ++raw) {
    if (M::year_from_raw(static_cast<std::uint8_t>(raw)) == year) {
      return static_cast<std::uint8_t>(raw);
    }
  }
  return 255;  // past the rule's range: the latest year it can say
}

// When the packet's first firing starts, relative to the packet time (the model's
// firing_offset_ns() of block 0 without its channel's own time).
template <class M>
std::int64_t first_firing_offset_ns(int returns) {
  if constexpr (kIsQt128<M>) {
    return PandarQT128::kFirstFiringNs;
  } else if constexpr (kIsXt<M>) {
    return M::firing_offset_ns(0, 0, returns) - M::kFirstChannelNs;
  } else {
    return M::firing_offset_ns(0, 0, returns) - M::kChannelOffsetNs[0];
  }
}

template <class M>
std::string list_rpms() {
  std::string text;
  for (const int rpm : M::kSupportedRpms)
    text += fmt::format("{}{}", text.empty() ? "" : " or ", rpm);
  return text;
}

template <class M>
std::string list_modes() {
  std::string text;
  for (const ReturnMode mode : M::kReturnModes)
    text += fmt::format("{}{}", text.empty() ? "" : ", ", to_string(mode));
  return text;
}

}  // namespace

template <class Model>
ModelSensor<Model>::ModelSensor(const ModelSensorConfig& config, const Calibration& calibration)
    : config_(config), calibration_(calibration) {
  const std::string_view name = display_name(Model::kId);
  if (std::find(Model::kSupportedRpms.begin(), Model::kSupportedRpms.end(), config_.rpm) ==
      Model::kSupportedRpms.end()) {
    throw std::invalid_argument(fmt::format("a simulated {} spins at {} RPM, not {}", name,
                                            list_rpms<Model>(), config_.rpm));
  }
  if (!mode_listed(Model::kReturnModes, config_.return_mode)) {
    throw std::invalid_argument(fmt::format("a simulated {} sends {} return, not '{}'", name,
                                            list_modes<Model>(), to_string(config_.return_mode)));
  }
  if (calibration_.channel_count != Model::kChannels) {
    throw std::invalid_argument(fmt::format("a {} calibration has {} channels, not {}", name,
                                            Model::kChannels, calibration_.channel_count));
  }
  returns_ = returns_per_firing(config_.return_mode);
  if constexpr (kIsQt128<Model>) {
    datagram_bytes_ = PandarQT128::layout(qt128_flags(config_.udp_sequence)).datagram_bytes;
  } else if constexpr (kIsXt<Model>) {
    datagram_bytes_ = Model::kDatagramBytes[0];
  } else {
    datagram_bytes_ = Model::kDatagramBytes[config_.udp_sequence ? 1 : 0];
  }
}

template <class Model>
std::size_t ModelSensor<Model>::next(std::span<std::uint8_t> out) {
  if (out.size() < datagram_bytes_) {
    throw std::invalid_argument(fmt::format("a {} datagram needs {} bytes, the buffer has {}",
                                            display_name(Model::kId), datagram_bytes_, out.size()));
  }
  std::uint8_t* const p = out.data();
  std::fill_n(p, datagram_bytes_, std::uint8_t{0});
  const ReturnMode mode = config_.return_mode;
  const bool last_first = kIsXt<Model> && mode == ReturnMode::kFirstLast;
  const std::uint64_t k = packets_++;
  const int firings = Model::kBlocks / returns_;
  const std::uint64_t first_firing = k * static_cast<std::uint64_t>(firings);

  // Header, and where blocks and units are.
  std::size_t block_bytes = 0, unit_bytes = 0;
  std::uint8_t mode_flag = 0;  // QT128: 1 when the packet's first firing is sequence 1
  p[0] = 0xEE;
  p[1] = 0xFF;
  if constexpr (std::is_same_v<Model, Pandar64>) {
    p[Model::kLaserCountOffset] = Model::kChannels;
    p[Model::kBlockCountOffset] = Model::kBlocks;
    p[Model::kDistanceUnitOffset] = kUnitMm;
    block_bytes = Model::kBlockBytes;
    unit_bytes = Model::kUnitBytes;
  } else {
    p[2] = Model::kProtocolMajor;
    p[3] = Model::kProtocolMinor;
    p[Model::kLaserCountOffset] = Model::kChannels;
    p[Model::kBlockCountOffset] = Model::kBlocks;
    p[8] = first_block_echo(mode, last_first);
    p[Model::kDistanceUnitOffset] = kUnitMm;
    p[10] = static_cast<std::uint8_t>(returns_);
    if constexpr (kIsQt128<Model>) {
      p[4] = 3;  // the capture's "status info version"
      p[Model::kFlagsOffset] = qt128_flags(config_.udp_sequence);
      const PandarQT128::Layout l = PandarQT128::layout(p[Model::kFlagsOffset]);
      block_bytes = l.block_bytes;
      unit_bytes = l.unit_bytes;
      mode_flag = first_firing % 2 == 0 ? 1 : 0;  // even firings are sequence 1
    } else {
      p[Model::kFlagsOffset] = 0x01;  // the XT's "always 0x01": UDP sequence present
      block_bytes = Model::kBlockBytes;
      unit_bytes = Model::kUnitBytes;
    }
  }
  const auto block = [&](int b) {
    return p + Model::kHeaderBytes + block_bytes * static_cast<std::size_t>(b);
  };

  // Blocks: one firing fills `returns_` blocks, all at its azimuth.
  const double step_cdeg = Model::azimuth_step_per_firing_cdeg(config_.rpm);
  double start_cdeg = std::fmod(config_.start_azimuth_deg * 100.0, 36000.0);
  if (start_cdeg < 0) start_cdeg += 36000.0;
  for (int j = 0; j < firings; ++j) {
    const std::uint64_t firing = first_firing + static_cast<std::uint64_t>(j);
    const double azimuth_cdeg =
        std::fmod(start_cdeg + static_cast<double>(firing) * step_cdeg, 36000.0);
    const auto azimuth = static_cast<std::uint16_t>(std::lround(azimuth_cdeg) % 36000);
    int sequence = 0;
    if constexpr (kIsQt128<Model>) {
      sequence = PandarQT128::firing_sequence(mode_flag, j * returns_, returns_);
    }
    for (int echo = 0; echo < returns_; ++echo)
      put_u16(block(j * returns_ + echo) + Model::kBlockAzimuthOffset, azimuth);
    for (int c = 0; c < Model::kChannels; ++c) {
      // A QT128 channel outside this firing's sequence did not fire: its unit stays 0.
      if (kIsQt128<Model> && !PandarQT128::fires(sequence, c)) continue;
      const RoomEchoes echoes = trace_room(
          calibration_.elevation_deg[static_cast<std::size_t>(c)],
          azimuth / 100.0 + calibration_.azimuth_offset_deg[static_cast<std::size_t>(c)]);
      // ±2 raw units (±8 mm) of noise, the same for every echo of a firing.
      const int noise =
          static_cast<int>(
              scene_hash(config_.seed ^ (firing * 256 + static_cast<std::uint64_t>(c))) % 5) -
          2;
      for (int echo = 0; echo < returns_; ++echo) {
        std::uint8_t* unit = block(j * returns_ + echo) + Model::kFirstUnitOffset +
                             unit_bytes * static_cast<std::size_t>(c);
        const RoomEcho e = pick(echoes, mode, echo, last_first);
        if (e.range_m > 0) {
          put_u16(unit,
                  static_cast<std::uint16_t>(std::max(1, range_to_raw(e.range_m, kUnitM) + noise)));
          unit[2] = e.reflectivity;
        }
        if constexpr (kIsXt<Model>) unit[3] = kXtConfidence;
      }
    }
  }

  // Tail: the packet time puts its first firing at the start time + firing × period.
  const std::int64_t t0 = config_.start_unix_ns +
                          static_cast<std::int64_t>(first_firing) * Model::kFiringPeriodNs -
                          first_firing_offset_ns<Model>(returns_);
  last_t0_ns_ = t0;
  const TailDateTime utc = tail_datetime_from_unix(t0 / 1'000'000'000);
  const auto micros = static_cast<std::uint32_t>((t0 % 1'000'000'000) / 1000);
  const auto rpm =
      static_cast<std::uint16_t>(config_.rpm + static_cast<int>(scene_hash(k / 97) % 5) - 2);
  const std::uint8_t date[6] = {raw_year<Model>(2000 + utc.year_since_2000),
                                utc.month,
                                utc.day,
                                utc.hour,
                                utc.minute,
                                utc.second};
  const std::uint32_t sequence_number = config_.first_sequence + static_cast<std::uint32_t>(k);
  if constexpr (kIsQt128<Model>) {
    const PandarQT128::Layout l = PandarQT128::layout(p[Model::kFlagsOffset]);
    std::uint8_t* const fs = p + *l.functional_safety_offset;
    fs[0] = 1;                                 // FS version
    fs[1] = static_cast<std::uint8_t>(k % 8);  // lidar state 0 (fine), rolling counter
    std::uint8_t* const t = p + l.tail_offset;
    t[Model::kModeFlagInTail] = mode_flag;
    t[Model::kReturnModeInTail] = static_cast<std::uint8_t>(mode);
    put_u16(t + Model::kMotorSpeedInTail, rpm);
    std::copy(std::begin(date), std::end(date), t + Model::kDateTimeInTail);
    put_u32(t + Model::kTimestampInTail, micros);
    t[Model::kFactoryInTail] = kFactory;
    if (l.sequence_offset) put_u32(p + *l.sequence_offset, sequence_number);
    PandarQT128::write_crcs(std::span(p, datagram_bytes_));
  } else {
    put_u16(p + Model::kMotorSpeedOffset, rpm);
    put_u32(p + Model::kTimestampOffset, micros);
    p[Model::kReturnModeOffset] = static_cast<std::uint8_t>(mode);
    p[Model::kFactoryOffset] = kFactory;
    std::copy(std::begin(date), std::end(date), p + Model::kDateTimeOffset);
    if (datagram_bytes_ >= Model::kSequenceOffset + 4) {
      put_u32(p + Model::kSequenceOffset, sequence_number);
    }
  }
  return datagram_bytes_;
}

template class ModelSensor<Pandar64>;
template class ModelSensor<PandarXT32>;
template class ModelSensor<PandarXT16>;
template class ModelSensor<PandarQT128>;

}  // namespace pandarcap
