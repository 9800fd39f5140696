#include "pipeline/held_out_lights.h"

#include <algorithm>
#include <cmath>
#include <set>

#include "core/elapsed.h"
#include "core/error.h"
#include "reconstruction/cast_shadows.h"

namespace u3mscan {
namespace {

// Photometric stereo needs three lights (docs/reconstruction.md); so does the check in
// CheckSideStack after the held-out lights are gone.
constexpr std::size_t kMinLightsLeft = 3;

// Throws InputError naming --hold-out-lights for an id that is not one of `known` (the side's
// lights, in order), or when fewer than kMinLightsLeft lights are left.
void CheckHeldOutIds(const std::vector<std::string>& known, const std::vector<std::string>& light_ids,
                     std::size_t lights_left, const std::string& side) {
  for (const std::string& id : light_ids) {
    if (std::find(known.begin(), known.end(), id) != known.end()) continue;
    std::string list;
    for (const std::string& k : known) list += (list.empty() ? "" : ", ") + k;
    throw InputError("command line", "--hold-out-lights",
                     "light ids of the capture's " + side + " side (" + list + "), got '" + id + "'");
  }
  if (lights_left < kMinLightsLeft) {
    throw InputError("command line", "--hold-out-lights",
                     "at least " + std::to_string(kMinLightsLeft) + " lights left to reconstruct the " + side +
                         " side from; holding out " + std::to_string(light_ids.size()) + " leaves " +
                         std::to_string(lights_left));
  }
}

}  // namespace

std::vector<Observation> TakeHeldOutObservations(Stack* stack, const std::vector<std::string>& light_ids) {
  std::vector<std::string> known;
  for (const LightModel& light : stack->lights) known.push_back(light.id);
  std::set<int> held;
  for (std::size_t k = 0; k < known.size(); ++k) {
    if (std::find(light_ids.begin(), light_ids.end(), known[k]) != light_ids.end()) held.insert(static_cast<int>(k));
  }
  std::set<int> lights_left;
  for (const Observation& o : stack->observations) {
    if (!held.count(o.light)) lights_left.insert(o.light);
  }
  CheckHeldOutIds(known, light_ids, lights_left.size(), stack->side);
  std::vector<Observation> kept, out;
  for (Observation& o : stack->observations) (held.count(o.light) ? out : kept).push_back(std::move(o));
  stack->observations = std::move(kept);
  return out;
}

std::vector<std::size_t> TakeHeldOutFrames(const Manifest& manifest, const std::string& side,
                                           const std::vector<std::string>& light_ids, std::vector<std::size_t>* side_frames) {
  std::vector<std::string> known;  // the side's lights, in the order their frames come
  std::set<std::string> left;
  std::vector<std::size_t> kept, out;
  for (std::size_t index : *side_frames) {
    const FrameSpec& spec = manifest.frames[index];
    const std::string id = spec.light ? *spec.light : std::string();
    if (std::find(known.begin(), known.end(), id) == known.end()) known.push_back(id);
    const bool held = std::find(light_ids.begin(), light_ids.end(), id) != light_ids.end();
    (held ? out : kept).push_back(index);
    if (!held) left.insert(id);
  }
  CheckHeldOutIds(known, light_ids, left.size(), side);
  *side_frames = std::move(kept);
  return out;
}

nlohmann::json HeldOutCheckToJson(const HeldOutCheck& check) {
  nlohmann::json lights = nlohmann::json::array();
  for (const HeldOutLightError& e : check.lights) {
    lights.push_back({{"id", e.light_id}, {"relative_rmse", e.relative_rmse}, {"pixels", e.pixels}});
  }
  return {{"relative_rmse", check.relative_rmse}, {"lights", lights}};
}

HeldOutCheck CheckHeldOutLights(const fitting::FitResult& fit, const Stack& stack, const SideReconstruction& geometry,
                                std::vector<Observation> held_out, const StageOptions& options) {
  const double start = SteadySeconds();
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
  const fitting::SurfaceGeometry surface = SideSurface(geometry);
  HeldOutSums sums;
  sums.Add(fit, check, surface);
  return sums.Finish(SteadySeconds() - start);
}

void HeldOutSums::Add(const fitting::FitResult& fit, const Stack& held_out, const fitting::SurfaceGeometry& geometry) {
  const auto fitted = fit.cluster_id.plane(0);
  for (const Observation& o : held_out.observations) {
    // Sums per light: several views of one light pool.
    const std::string& id = held_out.lights[o.light].id;
    const auto it = std::find_if(lights_.begin(), lights_.end(), [&](const HeldOutLightError& e) { return e.light_id == id; });
    const std::size_t k = static_cast<std::size_t>(it - lights_.begin());
    if (it == lights_.end()) {
      lights_.push_back({id, 0.0, 0});
      num_.push_back(0.0);
      den_.push_back(0.0);
    }
    const Image render = fitting::RenderFitted(fit, held_out, geometry, o);
    for (std::size_t i = 0; i < fitted.size(); ++i) {
      if (fitted[i] < 0.0f || (!o.flags.empty() && o.flags[i] != 0)) continue;
      double pixel_num = 0.0, pixel_den = 0.0;
      for (int c = 0; c < 3; ++c) {
        const double d = o.rgb.plane(c)[i], r = render.plane(c)[i];
        pixel_num += (r - d) * (r - d);
        pixel_den += d * d;
      }
      if (!std::isfinite(pixel_num) || !std::isfinite(pixel_den)) continue;
      num_[k] += pixel_num;
      den_[k] += pixel_den;
      ++lights_[k].pixels;
    }
  }
}

HeldOutCheck HeldOutSums::Finish(double seconds) const {
  HeldOutCheck out;
  out.lights = lights_;
  double num_all = 0.0, den_all = 0.0;
  for (std::size_t k = 0; k < lights_.size(); ++k) {
    out.lights[k].relative_rmse = den_[k] > 0.0 ? std::sqrt(num_[k] / den_[k]) : 0.0;
    num_all += num_[k];
    den_all += den_[k];
  }
  out.relative_rmse = den_all > 0.0 ? std::sqrt(num_all / den_all) : 0.0;
  out.seconds = seconds;
  return out;
}

}  // namespace u3mscan
