#pragma once
// The local shading frame of a pixel: z = the unit normal, x = the tangent, the axis of the
// Principled `anisotropic` stretch, y = z x x. The tangent is world +x projected into the tangent
// plane (world +y when the normal is nearly +x), then turned about the normal by the anisotropy
// rotation: counter-clockwise seen from above, from +x toward +y of the finished maps, which is
// U3M's `anisotropy_rotation` (degrees in 1.0; u3m/ converts for 1.1). The fitter, its re-renders
// and the benchmark's evaluation all shade in this frame.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cmath>

namespace u3mscan::fitting {

struct ShadingFrame {
  Eigen::Vector3d tangent;
  Eigen::Vector3d bitangent;
  Eigen::Vector3d normal;

  // A world direction in local coordinates (x along the tangent, z along the normal).
  Eigen::Vector3d ToLocal(const Eigen::Vector3d& world) const {
    return {world.dot(tangent), world.dot(bitangent), world.dot(normal)};
  }
};

// `unit_normal` must be unit length; `rotation_deg` is the anisotropy rotation (any value; the
// stretch repeats every 180 degrees).
inline ShadingFrame MakeShadingFrame(const Eigen::Vector3d& unit_normal, double rotation_deg = 0.0) {
  // Below this squared length the projected +x is too short to give a direction.
  constexpr double kDegenerateProjection = 1e-6;
  ShadingFrame f;
  f.normal = unit_normal;
  Eigen::Vector3d t = Eigen::Vector3d::UnitX() - unit_normal.x() * unit_normal;
  if (t.squaredNorm() < kDegenerateProjection) t = Eigen::Vector3d::UnitY() - unit_normal.y() * unit_normal;
  t.normalize();
  if (rotation_deg != 0.0) {
    const double a = rotation_deg * M_PI / 180.0;
    t = std::cos(a) * t + std::sin(a) * unit_normal.cross(t);
  }
  f.tangent = t;
  f.bitangent = unit_normal.cross(t);
  return f;
}

// `deg` in [0, 180): the anisotropic stretch is the same along t and -t.
inline double WrapHalfTurnDeg(double deg) {
  const double r = std::fmod(deg, 180.0);
  return r < 0.0 ? r + 180.0 : r;
}

// Local coordinates of a direction after the tangent is turned by `rotation_deg` about the normal,
// from its local coordinates before (the same turn as MakeShadingFrame's, applied to a vector
// already in the frame).
inline Eigen::Vector3d TurnTangent(const Eigen::Vector3d& local, double rotation_deg) {
  const double a = rotation_deg * M_PI / 180.0;
  const double c = std::cos(a), s = std::sin(a);
  return {c * local.x() + s * local.y(), -s * local.x() + c * local.y(), local.z()};
}

}  // namespace u3mscan::fitting
