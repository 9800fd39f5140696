#include "pipeline/relief_registration.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <vector>

#include "core/elapsed.h"
#include "core/units.h"
#include "reconstruction/cast_shadows.h"

namespace u3mscan {

double ViewTiltDeg(const Stack& stack, int view) {
  const Eigen::Vector3d centre = stack.grid.PixelCentreInWorld(stack.grid.width / 2, stack.grid.height / 2);
  const Eigen::Vector3d axis = stack.views.at(static_cast<std::size_t>(view)).centre_in_world_mm - centre;
  const double norm = axis.norm();
  return norm > 0.0 ? RadToDeg(std::acos(std::clamp(axis.z() / norm, -1.0, 1.0))) : 0.0;
}

int MostVerticalView(const Stack& stack) {
  int best = -1;
  double best_tilt = 1e300;
  for (int v = 0; v < static_cast<int>(stack.views.size()); ++v) {
    const double tilt = ViewTiltDeg(stack, v);
    if (tilt < best_tilt) best_tilt = tilt, best = v;
  }
  return best;
}

bool NeedsReliefRegistration(const Stack& stack) {
  if (stack.views.size() < 2) return false;
  for (int v = 0; v < static_cast<int>(stack.views.size()); ++v) {
    if (ViewTiltDeg(stack, v) > kReliefRegistrationMinTiltDeg) return true;
  }
  return false;
}

double ReliefTopMm(const Image& height_mm, const Image& valid) {
  constexpr double kTopQuantile = 0.999;
  std::vector<float> heights;
  heights.reserve(height_mm.pixel_count());
  const auto h = height_mm.plane(0);
  for (std::size_t i = 0; i < h.size(); ++i) {
    if (!std::isfinite(h[i])) continue;
    if (!valid.empty() && !(valid.plane(0)[i] >= 0.5f)) continue;
    heights.push_back(h[i]);
  }
  if (heights.empty()) return std::numeric_limits<double>::quiet_NaN();
  const std::size_t k = std::min(heights.size() - 1, static_cast<std::size_t>(kTopQuantile * heights.size()));
  std::nth_element(heights.begin(), heights.begin() + static_cast<std::ptrdiff_t>(k), heights.end());
  return heights[k];
}

Image ReliefHeightsMm(const Image& height_mm, const Image& valid, double surface_z_mm) {
  Image out(height_mm.width(), height_mm.height(), 1, static_cast<float>(surface_z_mm), height_mm.pitch_mm());
  const double top = ReliefTopMm(height_mm, valid);
  if (!std::isfinite(top)) return out;
  const auto h = height_mm.plane(0);
  auto z = out.plane(0);
  for (std::size_t i = 0; i < z.size(); ++i) {
    if (std::isfinite(h[i])) z[i] = static_cast<float>(surface_z_mm + (h[i] - top));
  }
  return out;
}

void UseTheMostVerticalViewForNormals(const Stack& stack, StageOptions* options) {
  options->photometric_stereo.view = MostVerticalView(stack);
  options->fit.refine_pixel_normals = false;
}

StepRecord TiltedViewNormalsStep() {
  return {"integration of the fitted normals", false,
          "a tilted view: the normals written are the most vertical view's photometric stereo (refined against the "
          "tilted view's observations they bend; docs/process.md, Relief registration)",
          0.0};
}

Stack SideViews(const PreparedCapture& prepared, const std::string& side) {
  Stack views;
  views.side = side;
  views.grid = prepared.calibration.grid;
  const Manifest& manifest = prepared.capture.manifest();
  for (const FrameSpec& spec : manifest.frames) {
    if (spec.role != FrameRole::kSample || spec.side != side) continue;
    const bool known = std::any_of(views.views.begin(), views.views.end(),
                                   [&spec](const ViewGeometry& v) { return v.camera_id == spec.camera; });
    const CameraCalibration* camera = prepared.calibration.FindCamera(spec.camera);
    if (!known && camera) views.views.push_back({spec.camera, camera->model.CentreInWorld()});
  }
  return views;
}

double MarkHiddenFromTiltedViews(const Image& surface_z_mm, Stack* stack) {
  return MarkHiddenFromTiltedViews(surface_z_mm, stack->grid, stack);
}

double MarkHiddenFromTiltedViews(const Image& surface_z_mm, const MetricGrid& height_grid, Stack* stack) {
  const std::size_t pixels = static_cast<std::size_t>(stack->grid.width) * stack->grid.height;
  // One "light" per tilted view, at its camera's centre: what it cannot light, the camera cannot see.
  Stack probe;
  probe.grid = stack->grid;
  std::vector<int> probe_of_view(stack->views.size(), -1);
  for (int v = 0; v < static_cast<int>(stack->views.size()); ++v) {
    if (ViewTiltDeg(*stack, v) <= kReliefRegistrationMinTiltDeg) continue;
    LightModel camera;
    camera.id = stack->views[static_cast<std::size_t>(v)].camera_id;
    camera.type = LightType::kPoint;
    camera.position_in_world_mm = stack->views[static_cast<std::size_t>(v)].centre_in_world_mm;
    probe_of_view[static_cast<std::size_t>(v)] = static_cast<int>(probe.lights.size());
    Observation o;
    o.view = v;
    o.light = static_cast<int>(probe.lights.size());
    o.flags.assign(pixels, 0);
    probe.lights.push_back(camera);
    probe.observations.push_back(std::move(o));
  }
  if (probe.observations.empty()) return 0.0;
  const reconstruction::CastShadowCounts hidden = reconstruction::MarkCastShadows(surface_z_mm, height_grid, &probe);
  for (Observation& o : stack->observations) {
    const int k = probe_of_view.at(static_cast<std::size_t>(o.view));
    if (k < 0) continue;
    if (o.flags.empty()) o.flags.assign(pixels, 0);
    const std::vector<std::uint8_t>& marks = probe.observations[static_cast<std::size_t>(k)].flags;
    for (std::size_t i = 0; i < pixels; ++i) {
      if (marks[i] & kCastShadow) o.flags[i] = static_cast<std::uint8_t>(o.flags[i] | kOutOfView);
    }
  }
  return hidden.share();
}

Stack BuildSideStackOnRelief(const PreparedCapture& prepared, const std::string& side, const StageOptions& options,
                             const Image& alpha, Stack on_plane, RunReport* report, const ProgressCallback& progress) {
  const double start = SteadySeconds();
  const int top = MostVerticalView(on_plane);
  const std::string top_id = on_plane.views.at(static_cast<std::size_t>(top)).camera_id;
  const double top_tilt = ViewTiltDeg(on_plane, top);
  StageOptions top_only = options;
  top_only.photometric_stereo.view = top;
  RunReport first_pass;  // its steps are this step's time, not the run's
  SideReconstruction relief = ReconstructSide(&on_plane, top_only, alpha, &first_pass, progress);
  const Image z = ReliefHeightsMm(relief.height_mm, relief.valid, prepared.calibration.surface_z_mm);
  on_plane = Stack();
  relief = SideReconstruction();
  float lo = 1e30f, hi = -1e30f;
  for (float v : z.plane(0)) lo = std::min(lo, v), hi = std::max(hi, v);
  const double reconstruct_seconds = SteadySeconds() - start;
  // The same frames pass the same checks again: their warnings are in the report already, from
  // the build on the face's plane; only the step is kept.
  RunReport rebuild;
  Stack stack = BuildSideStack(prepared, side, options, &rebuild, progress, z);
  report->steps.insert(report->steps.end(), rebuild.steps.begin(), rebuild.steps.end());
  const double hidden = MarkHiddenFromTiltedViews(z, &stack);
  char detail[300];
  std::snprintf(detail, sizeof detail,
                "heights from view %s alone (%.1f deg from the vertical): %.3f to %.3f mm, top on the face z = %.3f mm; "
                "every view rectified at them; %.2f %% of the tilted views' pixels hidden by the relief",
                top_id.c_str(), top_tilt, static_cast<double>(lo), static_cast<double>(hi),
                prepared.calibration.surface_z_mm, 100.0 * hidden);
  report->steps.push_back({"relief registration " + side, true, detail, reconstruct_seconds});
  return stack;
}

}  // namespace u3mscan
