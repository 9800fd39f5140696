#pragma once
// Closed-form geometry of the analytic presets (flat_lambertian, sphere_cap, bumps), so that
// integration tests can compare reconstructed normals and heights with exact values.
// Positions in mm on the scene grid (x right, y up; see scene.h), normals unit, world frame.

#include <array>

#include "datasets_synthetic/scene.h"

namespace u3mscan::synthetic {

// `bumps`: h(x, y) = amplitude * (1 + cos(2 pi x / period) cos(2 pi y / period)), an egg-crate
// that is smooth everywhere (slopes up to amplitude * 2 pi / period = 0.47).
inline constexpr double kBumpsAmplitudeMm = 0.15;
inline constexpr double kBumpsPeriodMm = 2.0;
double BumpsHeightMm(double x_mm, double y_mm);
std::array<double, 3> BumpsNormal(double x_mm, double y_mm);

// `sphere_cap`: one spherical cap centred on the grid, base radius 0.4 * the shorter grid side,
// height min(1 mm, base radius / 4), on a flat plane at height 0. The rim is a crease: normals
// there are only defined one pixel away from it.
struct SphereCap {
  double center_x_mm = 0.0;
  double center_y_mm = 0.0;
  double base_radius_mm = 0.0;
  double cap_height_mm = 0.0;
  double sphere_radius_mm = 0.0;  // (base_radius^2 + cap_height^2) / (2 cap_height)
};
SphereCap SphereCapFor(const SceneOptions& options);
double SphereCapHeightMm(const SphereCap& cap, double x_mm, double y_mm);
std::array<double, 3> SphereCapNormal(const SphereCap& cap, double x_mm, double y_mm);

}  // namespace u3mscan::synthetic
