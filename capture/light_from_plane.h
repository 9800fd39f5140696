#pragma once
// A point light's distance along a mirror sphere's reflected ray, from the white target (a flat
// frame) lying in the known sample plane z = 0 under that light.
//
// One sphere placement fixes the line the light lies on (p = c + t r: c the highlight point on the
// sphere, r the unit reflected direction, world mm) but hardly its distance t. The flat frame
// shows the light's shading over the whole target, a Lambertian plane:
//   v(x) = k * cos(theta_i(x)) * profile(x) / |x - p|^2 * vignetting(u(x))
// (x on z = 0, u(x) its camera pixel through the known pose; k = exposure * rho / pi * intensity).
// Its shape across the target depends on t (the inverse square and the cosine change their
// gradient with the distance). Here t is found by a 1-D search, with the scale k and the lens's
// vignetting (even, radial about the principal point: 1 + a1 rho^2 + a2 rho^4, rho = distance over
// the image half-diagonal) solved in closed form (linear least squares, relative residuals) at
// each t. When the light has no profile in the manifest, its exponent n (cos^n about an axis
// toward the target's centre) is searched too, nested. The target is sampled on a coarse grid of
// world points (a few hundred), projected into the frame.
//
// The fit's 1-sigma on t comes from the curvature of the residual sum (every other unknown
// minimised out) and the residuals' own scatter; a fit whose sigma on t exceeds
// PlaneLightFitOptions::max_relative_sigma of the distance, or whose minimum lies on the edge of
// the search, is refused (ok = false, reason says why) and the caller keeps the sphere's result.

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "capture/camera_model.h"
#include "core/image.h"
#include "core/stack.h"

namespace u3mscan {

struct PlaneLightFitOptions {
  int samples_per_side = 20;  // target sample grid (20 x 20 = 400 points before masking)
  // Keep this fraction of the region's border out (the target's edge, a frame's last pixels).
  double margin_fraction = 0.05;
  int min_samples = 50;
  // Search range of the distance along the ray, as multiples of the start distance.
  double min_distance_factor = 0.25, max_distance_factor = 4.0;
  // Refused above this 1-sigma of t as a fraction of t: the issue asks for 1 % of the distance,
  // and a looser fit is no better than a design value (the manifest prior's default is 10 mm,
  // 2.5 % at 400 mm). The whole view of the synthetic near rig gives 0.14-0.33 %; 4 x 4 mm of it,
  // 2.6 % (LightFromPlane tests).
  double max_relative_sigma = 0.01;
  double max_profile_exponent = 40.0;  // search range of n when the manifest gives no profile
};

struct PlaneLightFit {
  bool ok = false;
  std::string reason;           // why not ok (names the frame)
  LightModel model;             // start with the position (and exponent, when fitted) replaced
  double distance_mm = 0.0;     // t: from the highlight point along the ray
  double sigma_mm = 0.0;        // 1-sigma of t
  double residual_rms = 0.0;    // RMS relative residual of the shading fit (fraction of the value)
  int samples = 0;              // target points used
  bool exponent_fitted = false; // the manifest gave no profile: n was fitted
  std::array<double, 2> vignetting{};  // a1, a2 fitted (nuisance)
};

// `flat_rgb`: the flat frame of `camera` under `start`'s light, dark-subtracted (frame units);
// `saturated` its saturation mask (width*height, may be empty). `region_mm` = [x0, y0, x1, y1]
// of the sample plane the white target covers. `ray_origin_mm` / `ray_direction` (unit): the
// sphere's reflected ray; start.position_in_world_mm's distance along it seeds the search.
PlaneLightFit FitPointLightOnPlane(const Image& flat_rgb, const std::vector<std::uint8_t>& saturated,
                                   const CameraModel& camera, const LightModel& start,
                                   const Eigen::Vector3d& ray_origin_mm, const Eigen::Vector3d& ray_direction,
                                   const std::array<double, 4>& region_mm, const std::string& frame_file,
                                   const PlaneLightFitOptions& options = {});

}  // namespace u3mscan
