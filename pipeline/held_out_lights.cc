#include "pipeline/held_out_lights.h"

#include <algorithm>
#include <cmath>
#include <set>

#include "core/error.h"
#include "reconstruction/cast_shadows.h"

namespace u3mscan {
namespace {

// Photometric stereo needs three lights (docs/reconstruction.md); so does the check in
// CheckSideStack after the held-out lights are gone.
constexpr std::size_t kMinLightsLeft = 3;

std::string LightList(const Stack& stack) {
  std::string out;
  for (const LightModel& light : stack.lights) out += (out.empty() ? "" : ", ") + light.id;
  return out;
}

}  // namespace

std::vector<Observation> TakeHeldOutObservations(Stack* stack, const std::vector<std::string>& light_ids) {
  std::set<int> held;
  for (const std::string& id : light_ids) {
    const auto it = std::find_if(stack->lights.begin(), stack->lights.end(), [&](const LightModel& l) { return l.id == id; });
    if (it == stack->lights.end()) {
      throw InputError("command line", "--hold-out-lights",
                       "light ids of the capture's " + stack->side + " side (" + LightList(*stack) + "), got '" + id + "'");
    }
    held.insert(static_cast<int>(it - stack->lights.begin()));
  }
  std::vector<Observation> kept, out;
  std::set<int> lights_left;
  for (Observation& o : stack->observations) {
    if (held.count(o.light)) {
      out.push_back(std::move(o));
    } else {
      lights_left.insert(o.light);
      kept.push_back(std::move(o));
    }
  }
  if (lights_left.size() < kMinLightsLeft) {
    throw InputError("command line", "--hold-out-lights",
                     "at least " + std::to_string(kMinLightsLeft) + " lights left to reconstruct the " + stack->side +
                         " side from; holding out " + std::to_string(held.size()) + " leaves " +
                         std::to_string(lights_left.size()));
  }
  stack->observations = std::move(kept);
  return out;
}

HeldOutCheck CheckHeldOutLights(const fitting::FitResult& fit, const Stack& stack, const SideReconstruction& geometry,
                                std::vector<Observation> held_out, const StageOptions& options) {
  const double start = StageClock();
  // The held-out observations on the fitted stack's grid, lights and views (light indices kept).
  Stack check;
  check.side = stack.side;
  check.grid = stack.grid;
  check.lights = stack.lights;
  check.views = stack.views;
  check.observations = std::move(held_out);
  if (options.mark_cast_shadows && !geometry.height_mm.empty()) {
    reconstruction::MarkCastShadows(geometry.height_mm, &check, options.cast_shadows);
  }
  const fitting::SurfaceGeometry surface{geometry.photometric_stereo.normal, geometry.photometric_stereo.albedo,
                                         geometry.height_mm};
  HeldOutCheck out;
  // Sums per light (several views of one light pool), then over every light.
  std::vector<double> num, den;
  double num_all = 0.0, den_all = 0.0;
  const auto fitted = fit.cluster_id.plane(0);
  for (const Observation& o : check.observations) {
    const std::string& id = check.lights[o.light].id;
    const auto it = std::find_if(out.lights.begin(), out.lights.end(), [&](const HeldOutLightError& e) { return e.light_id == id; });
    const std::size_t k = static_cast<std::size_t>(it - out.lights.begin());
    if (it == out.lights.end()) {
      out.lights.push_back({id, 0.0, 0});
      num.push_back(0.0);
      den.push_back(0.0);
    }
    const Image render = fitting::RenderFitted(fit, check, surface, o);
    for (std::size_t i = 0; i < fitted.size(); ++i) {
      if (fitted[i] < 0.0f || (!o.flags.empty() && o.flags[i] != 0)) continue;
      double pixel_num = 0.0, pixel_den = 0.0;
      for (int c = 0; c < 3; ++c) {
        const double d = o.rgb.plane(c)[i], r = render.plane(c)[i];
        pixel_num += (r - d) * (r - d);
        pixel_den += d * d;
      }
      if (!std::isfinite(pixel_num) || !std::isfinite(pixel_den)) continue;
      num[k] += pixel_num;
      den[k] += pixel_den;
      ++out.lights[k].pixels;
    }
  }
  for (std::size_t k = 0; k < out.lights.size(); ++k) {
    out.lights[k].relative_rmse = den[k] > 0.0 ? std::sqrt(num[k] / den[k]) : 0.0;
    num_all += num[k];
    den_all += den[k];
  }
  out.relative_rmse = den_all > 0.0 ? std::sqrt(num_all / den_all) : 0.0;
  out.seconds = StageClock() - start;
  return out;
}

}  // namespace u3mscan
