#pragma once
// Lights held out of a run (`u3mscan process --hold-out-lights`): their photographs take no part in
// photometric stereo or the fit, and are compared afterwards with the fitted material rendered
// under the same light. This measures the material against real photographs it was not made
// from, on any capture (no ground truth needed): the issue's "re-rendered images of lights left
// out of the fit".
//
// Error of one light: sqrt(sum (render - data)^2 / sum data^2), linear RGB, over the pixels where
// the material was fitted and the observation is usable (not saturated, not out of view, not in a
// cast shadow of the integrated height when the run marks shadows); all lights: the same sums
// pooled.

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "capture/manifest.h"
#include "core/stack.h"
#include "fitting/principled_fit.h"
#include "pipeline/stages.h"

namespace u3mscan {

struct HeldOutLightError {
  std::string light_id;
  double relative_rmse = 0.0;
  std::size_t pixels = 0;  // pixels compared (over every view of the light)
};

struct HeldOutCheck {
  std::vector<HeldOutLightError> lights;  // in the order of their first observation
  double relative_rmse = 0.0;             // pooled over the lights
  double seconds = 0.0;
};

// Moves the observations of the lights named in `light_ids` out of `stack` (every view). Throws
// InputError naming `--hold-out-lights` for an id that is not one of the stack's lights, or when
// fewer than three lights would be left to reconstruct from.
std::vector<Observation> TakeHeldOutObservations(Stack* stack, const std::vector<std::string>& light_ids);

// The banded path's form: moves the frames (indices into manifest.frames) of `side_frames` that the
// named lights lit out of it and returns them. Throws as TakeHeldOutObservations does.
std::vector<std::size_t> TakeHeldOutFrames(const Manifest& manifest, const std::string& side,
                                           const std::vector<std::string>& light_ids, std::vector<std::size_t>* side_frames);

// The check as report.json's and fit.json's "held_out_lights": {"relative_rmse", "lights": [{"id",
// "relative_rmse", "pixels"}]}, errors as fractions (0.02 = 2 %).
nlohmann::json HeldOutCheckToJson(const HeldOutCheck& check);

// Renders every held-out observation with `fit` on `geometry` (the reconstruction of `stack`, the
// fitted observations' stack) and compares (see above). Marks the held-out observations' cast
// shadows from geometry.height_mm first when options.mark_cast_shadows.
HeldOutCheck CheckHeldOutLights(const fitting::FitResult& fit, const Stack& stack, const SideReconstruction& geometry,
                                std::vector<Observation> held_out, const StageOptions& options);

// The comparison of CheckHeldOutLights summed over bands (pipeline/tiled_side.h): Add each band's
// held-out observations (a Stack on the band's grid, cast shadows already marked) with the band's
// fit and geometry, then Finish.
class HeldOutSums {
 public:
  void Add(const fitting::FitResult& fit, const Stack& held_out, const fitting::SurfaceGeometry& geometry);
  HeldOutCheck Finish(double seconds) const;

 private:
  std::vector<HeldOutLightError> lights_;  // in the order of their first observation
  std::vector<double> num_, den_;          // per light
};

}  // namespace u3mscan
