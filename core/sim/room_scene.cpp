// The room's geometry (room_scene.hpp): ray against box, pillar and fence.
#include "core/sim/room_scene.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

namespace pandarcap {

namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;

}  // namespace

std::uint64_t scene_hash(std::uint64_t x) noexcept {
  x += 0x9E3779B97F4A7C15ULL;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ULL;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBULL;
  return x ^ (x >> 31);
}

std::uint16_t range_to_raw(double range_m, double unit_m) noexcept {
  return static_cast<std::uint16_t>(std::clamp(std::lround(range_m / unit_m), 1L, 65535L));
}

RoomEchoes trace_room(double elevation_deg, double azimuth_deg) noexcept {
  using namespace room;
  const double ce = std::cos(elevation_deg * kDegToRad);
  const double dx = ce * std::sin(azimuth_deg * kDegToRad);
  const double dy = ce * std::cos(azimuth_deg * kDegToRad);
  const double dz = std::sin(elevation_deg * kDegToRad);
  constexpr double kInf = std::numeric_limits<double>::infinity();

  // The room is a box around the origin: the nearest plane along the ray is the surface hit.
  const double tx = dx > 0 ? kWallXMax / dx : dx < 0 ? kWallXMin / dx : kInf;
  const double ty = dy > 0 ? kWallYMax / dy : dy < 0 ? kWallYMin / dy : kInf;
  const double tz = dz > 0 ? kCeilingZ / dz : dz < 0 ? kFloorZ / dz : kInf;
  double t = std::min({tx, ty, tz});
  std::uint8_t reflectivity =
      t == tz ? (dz < 0 ? kFloorReflectivity : kCeilingReflectivity) : kWallReflectivity;
  if (t == ty && dy > 0) {
    const double x = t * dx, z = t * dz;
    if (x > kDoorXMin && x < kDoorXMax && z < kDoorTopZ) t = kInf;  // out through the doorway
  }

  // Pillar: |(t·dx, t·dy) - centre| = radius, nearest positive root.
  const double a = dx * dx + dy * dy;
  if (a > 0) {
    const double b = -2 * (dx * kPillarX + dy * kPillarY);
    const double c = kPillarX * kPillarX + kPillarY * kPillarY - kPillarRadius * kPillarRadius;
    const double disc = b * b - 4 * a * c;
    if (disc >= 0) {
      const double root = (-b - std::sqrt(disc)) / (2 * a);
      if (root > 0 && root < t && root * dz > kFloorZ && root * dz < kCeilingZ) {
        t = root;
        reflectivity = kPillarReflectivity;
      }
    }
  }

  RoomEchoes echoes;
  if (std::isinf(t)) return echoes;
  echoes.last = {t, reflectivity};
  echoes.strongest = echoes.last;
  if (dx > 0) {
    const double tf = kFenceX / dx;
    const double y = tf * dy, z = tf * dz;
    if (tf < t && y > kFenceYMin && y < kFenceYMax && z < kFenceTopZ) {
      echoes.strongest = {tf, kFenceReflectivity};
    }
  }
  return echoes;
}

}  // namespace pandarcap
