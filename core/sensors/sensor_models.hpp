// Every supported model in one place, and the one switch on the model: with_model(id, f) calls
// f(std::type_identity<Model>{}) with the model's type, so a caller builds its model's decoder
// (or table, or simulator) once, when the model is known, and everything after runs on the
// type: no per-packet virtual call, no per-packet branch on the model.
//
//   with_model(SensorModelId::kPandarXT32, [&]<class M>(std::type_identity<M>) {
//     run_decode_loop<M>(...);  // M::validate, M::azimuth_cdeg, ... inlined
//   });
//
// The members every model type has (pandar40p.hpp ... pandar_qt128.hpp; tests/test_sensor_models
// checks them on the real captures): kId, kChannels, kBlocks, kMaxPointsPerPacket,
// kMaxDatagramBytes, kDatagramBytes (QT128: layout(flags)), kMinRangeM, kMaxRangeM,
// kSupportedRpms, kReturnModes, kNominalElevationDeg, kNominalAzimuthOffsetDeg, kFiringPeriodNs;
// validate(p); on a valid p: azimuth_cdeg(p, b), distance_raw(p, b, c), reflectivity(p, b, c),
// distance_unit_m(p), motor_rpm(p), timestamp_us(p), return_mode(p), factory(p), utc(p),
// year_from_raw(raw), sequence(p), high_temperature(p), firing_offset_ns(p, b, c, returns);
// packet_period_ns(returns), packets_per_second(returns), packets_per_revolution(returns, rpm),
// azimuth_step_per_packet_cdeg(returns, rpm), azimuth_step_per_firing_cdeg(rpm).
#pragma once

#include <algorithm>
#include <cstddef>
#include <type_traits>

#include "core/sensors/pandar40p.hpp"
#include "core/sensors/pandar64.hpp"
#include "core/sensors/pandar_qt128.hpp"
#include "core/sensors/pandar_xt.hpp"
#include "core/sensors/sensor_model_id.hpp"

namespace pandarcap {

template <class F>
constexpr decltype(auto) with_model(SensorModelId id, F&& f) {
  switch (id) {
    case SensorModelId::kPandar64:
      return f(std::type_identity<Pandar64>{});
    case SensorModelId::kPandarXT32:
      return f(std::type_identity<PandarXT32>{});
    case SensorModelId::kPandarXT16:
      return f(std::type_identity<PandarXT16>{});
    case SensorModelId::kPandarQT128:
      return f(std::type_identity<PandarQT128>{});
    case SensorModelId::kPandar40P:
      break;
  }
  return f(std::type_identity<Pandar40P>{});
}

// The largest datagram of any supported model: the ring's slot size. The 40P's 1266 bytes.
inline constexpr std::size_t kLargestDatagramBytes = std::max(
    {Pandar40P::kMaxDatagramBytes, Pandar64::kMaxDatagramBytes, PandarXT32::kMaxDatagramBytes,
     PandarXT16::kMaxDatagramBytes, PandarQT128::kMaxDatagramBytes});
// The most points one packet can hold (the 40P's 10 × 40).
inline constexpr int kLargestPointsPerPacket = std::max(
    {Pandar40P::kMaxPointsPerPacket, Pandar64::kMaxPointsPerPacket, PandarXT32::kMaxPointsPerPacket,
     PandarXT16::kMaxPointsPerPacket, PandarQT128::kMaxPointsPerPacket});

// What the rest of pandarcap relies on, checked where the models are.
template <class M>
constexpr bool model_fits() {
  return M::kChannels <= kMaxChannels &&  // and so Point::channel, a u8, stays < 128
         M::kNominalElevationDeg.size() == static_cast<std::size_t>(M::kChannels) &&
         M::kNominalAzimuthOffsetDeg.size() == static_cast<std::size_t>(M::kChannels);
}
static_assert(model_fits<Pandar40P>() && model_fits<Pandar64>() && model_fits<PandarXT32>() &&
              model_fits<PandarXT16>() && model_fits<PandarQT128>());
static_assert(Pandar40P::kId == SensorModelId::kPandar40P &&
              Pandar64::kId == SensorModelId::kPandar64 &&
              PandarXT32::kId == SensorModelId::kPandarXT32 &&
              PandarXT16::kId == SensorModelId::kPandarXT16 &&
              PandarQT128::kId == SensorModelId::kPandarQT128);
static_assert(kLargestDatagramBytes == kMaxPacketBytes, "the ring's slot stays the 40P's");

// Channels of a model known only at run time (the calibration's row count).
constexpr int channel_count(SensorModelId id) {
  return with_model(id, []<class M>(std::type_identity<M>) { return M::kChannels; });
}

}  // namespace pandarcap
