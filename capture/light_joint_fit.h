#pragma once
// Joint refinement of every light and every mirror-sphere placement of a capture (Ceres).
//
// Each light is seen on the same few sphere placements (sphere_p0_L00 ... sphere_p2_L15): a
// placement's centre found in one frame carries that frame's rim noise and turns into an error of
// every ray reflected off it (0.005 mm on a 7 mm sphere is ~0.1 deg of reflected ray). Here the
// placements (grouped by where their centres were found) share one centre, and all lights and
// all placement centres are fitted together: every highlight's reflected ray must point at its
// light, each ray weighted by its angular uncertainty (LightFitOptions::highlight_sigma_px, rescaled
// by the highlights' own scatter where they over-determine the fit), each placement's centre held
// loosely near the mean of its frames' rim fits (centre_prior_sigma_of_radius), each point light
// near the manifest's position (manifest_position_sigma_mm). Centres given by the manifest (not
// found in a frame) stay fixed, as does every centre's height. docs/calibration.md, "Joint fit".

#include <vector>

#include "capture/light_calibration.h"

namespace u3mscan {

struct JointLightInput {
  LightModel start;                            // id, type, manifest position/direction
  std::vector<SphereObservation> observations;  // this light's sphere frames (may be empty)
};

struct JointLightFit {
  std::vector<LightFit> lights;  // one per input, same order (an input without observations: start)
  int placements = 0;            // distinct sphere placements found
  std::vector<Eigen::Vector3d> placement_centres_mm;  // refined (world mm), in the order found
  double centre_shift_rms_mm = 0;  // how far the joint fit moved the placements' centres
  bool converged = false;
  // The highlights' sigma actually used, as a fraction of LightFitOptions::highlight_sigma_px:
  // sqrt(chi^2 / dof) of the highlight residuals when they over-determine the fit, clamped to
  // [0.02, 1]; 1 otherwise. The lights' notes (1-sigma) use it.
  double sigma_scale = 1.0;
};

// `per_light[i].observations` must hold SphereObservation::camera_centre_in_world_mm. Placements
// are grouped by their centres (within half a radius). Without any free centre and with one
// light the result equals FitPointLight / FitDirectionalLight's up to the reweighting.
JointLightFit FitLightsJointly(const std::vector<JointLightInput>& per_light, const LightFitOptions& options = {});

}  // namespace u3mscan
