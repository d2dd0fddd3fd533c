// The room every simulated sensor sees (the Pandar40P's SyntheticSensor and the other models'
// ModelSensor): one scene, so a test or a demo of any model finds the same surfaces, and the
// echoes a ray gets from them. Pure geometry in metres: each simulator turns ranges into its
// model's raw units and adds its own noise.
//
// The sensor sits at the origin, 1.8 m above the floor (hesai frame: y at azimuth 0, x at 90°,
// z up, azimuth clockwise seen from above):
//   walls x = -12 m / +18 m, y = -7 m / +9 m, floor z = -1.8 m, ceiling z = +3.0 m;
//   a doorway in the +y wall (x 0..4 m, up to 2.2 m above the floor) through which beams return
//   nothing;
//   a pillar of radius 0.5 m at (5, 3);
//   a wire fence at x = +4 m, y -6..-2 m, up to 2 m high, that returns the strongest echo while
//   the wall behind it returns the last echo (so dual-return modes carry two different echoes
//   there, and identical ones everywhere else, as real sensors do).
// Each surface has its own reflectivity (below), so a test can tell from a point's intensity
// which surface it must lie on.
#pragma once

#include <cstdint>

namespace pandarcap {

namespace room {

inline constexpr double kFloorZ = -1.8, kCeilingZ = 3.0;
inline constexpr double kWallXMin = -12.0, kWallXMax = 18.0, kWallYMin = -7.0, kWallYMax = 9.0;
inline constexpr double kDoorXMin = 0.0, kDoorXMax = 4.0, kDoorTopZ = kFloorZ + 2.2;
inline constexpr double kPillarX = 5.0, kPillarY = 3.0, kPillarRadius = 0.5;
inline constexpr double kFenceX = 4.0, kFenceYMin = -6.0, kFenceYMax = -2.0,
                        kFenceTopZ = kFloorZ + 2.0;

inline constexpr std::uint8_t kFloorReflectivity = 20;
inline constexpr std::uint8_t kCeilingReflectivity = 40;
inline constexpr std::uint8_t kWallReflectivity = 60;
inline constexpr std::uint8_t kFenceReflectivity = 120;
inline constexpr std::uint8_t kPillarReflectivity = 200;

}  // namespace room

// One echo: its range along the ray and the surface's reflectivity; range 0: nothing returns.
struct RoomEcho {
  double range_m = 0.0;
  std::uint8_t reflectivity = 0;
};

// The echoes of one ray. Where the fence is in front of a wall, `strongest` is the fence and
// `last` the wall; elsewhere both are the one surface hit.
struct RoomEchoes {
  RoomEcho strongest, last;
  // The nearest echo (the "first" of the modes that report one): the fence where it is there.
  RoomEcho first() const noexcept { return strongest.range_m < last.range_m ? strongest : last; }
};

// The echoes along the ray at `elevation_deg` (up-positive) and `azimuth_deg` (clockwise from +y).
RoomEchoes trace_room(double elevation_deg, double azimuth_deg) noexcept;

// A range in raw units of `unit_m` (rounded, kept to 1..65535: a hit never reads as "no return").
std::uint16_t range_to_raw(double range_m, double unit_m) noexcept;

// splitmix64: a small, well-mixed hash, for the simulators' deterministic noise.
std::uint64_t scene_hash(std::uint64_t x) noexcept;

}  // namespace pandarcap
