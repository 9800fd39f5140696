#include "pipeline/stages.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "core/elapsed.h"
#include "core/error.h"
#include "core/logging.h"
#include "fitting/tiled_fit.h"

namespace u3mscan {

namespace {

// Degenerate captures that cannot give a material are refused (InputError) before any output.
constexpr int kMinCameraPixels = 2;        // per image side: a 1-pixel image has no surface to measure
constexpr int kMinDistinctLights = 3;      // photometric stereo needs three light directions
// A sample frame whose mean signal, divided by the cosine of its light at the sample centre, is
// below this fraction of the median of the side's frames carries no signal (a light that did not
// fire, a lens cap): it is left out with a warning instead of pulling every pixel toward black.
constexpr double kNoSignalFraction = 0.02;
constexpr double kMinLightCosine = 0.05;   // floor of that cosine (lights at grazing elevations)

std::string ManifestPath(const PreparedCapture& prepared) { return (prepared.capture.folder() / kManifestFileName).string(); }

// Mean of the observation's unflagged pixels over the colour channels, per unit cosine of its light.
double SignalPerCosine(const Stack& stack, const Observation& o) {
  double sum = 0.0;
  std::size_t n = 0;
  for (std::size_t i = 0; i < o.rgb.pixel_count(); ++i) {
    if (!o.flags.empty() && o.flags[i] != 0) continue;
    sum += o.rgb.plane(0)[i] + o.rgb.plane(1)[i] + o.rgb.plane(2)[i];
    ++n;
  }
  const LightModel& light = stack.lights[static_cast<std::size_t>(o.light)];
  const Eigen::Vector3d centre(0.0, 0.0, 0.0);
  const double cosine = std::max(kMinLightCosine, light.DirectionFrom(centre).z());
  return n ? sum / (3.0 * static_cast<double>(n)) / cosine : 0.0;
}

}  // namespace

PreparedCapture PrepareCapture(const std::filesystem::path& capture_dir, StageOptions& options, RunReport* report,
                               const ProgressCallback& progress) {
  double start = SteadySeconds();
  Capture capture = Capture::Open(capture_dir, options.capture);
  report->steps.push_back({"read manifest", true, std::to_string(capture.frame_count()) + " frames listed", SteadySeconds() - start});

  std::vector<std::string> sides;
  for (const char* side : {"front", "back"}) {
    FrameFilter filter;
    filter.role = FrameRole::kSample;
    filter.side = side;
    if (!capture.Frames(filter).empty()) sides.push_back(side);
  }
  if (sides.empty()) {
    throw InputError((capture.folder() / "capture.json").string(), "/frames", "at least one frame with role \"sample\"");
  }
  const Manifest& manifest = capture.manifest();
  for (std::size_t c = 0; c < manifest.cameras.size(); ++c) {
    const CameraSpec& camera = manifest.cameras[c];
    if (camera.width < kMinCameraPixels || camera.height < kMinCameraPixels) {
      throw InputError((capture.folder() / kManifestFileName).string(), "/cameras/" + std::to_string(c),
                       "a camera image of at least " + std::to_string(kMinCameraPixels) + " x " +
                           std::to_string(kMinCameraPixels) + " pixels, got " + std::to_string(camera.width) + " x " +
                           std::to_string(camera.height));
    }
  }
  for (const std::string& side : sides) {
    FrameFilter filter;
    filter.role = FrameRole::kSample;
    filter.side = side;
    std::vector<std::string> lights;
    for (std::size_t index : capture.Frames(filter)) {
      const auto& light = capture.frame(index).light;
      if (light && std::find(lights.begin(), lights.end(), *light) == lights.end()) lights.push_back(*light);
    }
    if (static_cast<int>(lights.size()) < kMinDistinctLights) {
      throw InputError((capture.folder() / kManifestFileName).string(), "/frames",
                       "sample frames of side " + side + " under at least " + std::to_string(kMinDistinctLights) +
                           " different lights (photometric stereo needs three light directions), got " +
                           std::to_string(lights.size()));
    }
  }
  if (sides.size() == 1 && sides[0] == "front") {
    report->steps.push_back({"back side", false, "the capture has no back-side sample frames: back = front", 0.0});
  }

  start = SteadySeconds();
  CalibrationResult calibration = Calibrate(capture, options.calibration, progress);
  const double calibrate_s = SteadySeconds() - start;
  for (const StepReport& step : calibration.steps) {
    report->steps.push_back({"calibration: " + step.step, step.ran, step.detail, 0.0});
  }
  report->steps.push_back({"calibration (total)", true, "", calibrate_s});
  for (const std::string& warning : calibration.warnings) report->warnings.push_back(warning);
  report->calibration = calibration.ToJson();
  return PreparedCapture{std::move(capture), std::move(calibration), std::move(sides)};
}

std::vector<std::size_t> CheckSideStack(const PreparedCapture& prepared, const std::string& side,
                                        const StageOptions& options, Stack* stack_in, RunReport* report) {
  Stack& stack = *stack_in;
  std::vector<std::size_t> kept_indices;
  for (std::size_t k = 0; k < stack.observations.size(); ++k) kept_indices.push_back(k);
  // Frames without signal are left out (see kNoSignalFraction).
  if (stack.observations.size() >= 2) {
    std::vector<double> signal(stack.observations.size());
    for (std::size_t k = 0; k < signal.size(); ++k) signal[k] = SignalPerCosine(stack, stack.observations[k]);
    std::vector<double> sorted = signal;
    std::nth_element(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2), sorted.end());
    const double median = sorted[sorted.size() / 2];
    std::vector<Observation> kept;
    kept_indices.clear();
    for (std::size_t k = 0; k < signal.size(); ++k) {
      if (median > 0.0 && signal[k] < kNoSignalFraction * median) {
        const Observation& o = stack.observations[k];
        report->warnings.push_back("side " + side + ", light " + stack.lights[static_cast<std::size_t>(o.light)].id +
                                   ", view " + stack.views[static_cast<std::size_t>(o.view)].camera_id +
                                   ": the sample frame carries no signal (" + std::to_string(signal[k] / median) +
                                   " of the median frame): left out; did the light fire?");
        continue;
      }
      kept.push_back(std::move(stack.observations[k]));
      kept_indices.push_back(k);
    }
    stack.observations = std::move(kept);
  }
  std::vector<int> lights;
  for (const Observation& o : stack.observations) {
    if (std::find(lights.begin(), lights.end(), o.light) == lights.end()) lights.push_back(o.light);
  }
  if (static_cast<int>(lights.size()) < kMinDistinctLights) {
    throw InputError(ManifestPath(prepared), "/frames",
                     "sample frames of side " + side + " with signal under at least " +
                         std::to_string(kMinDistinctLights) + " different lights, got " + std::to_string(lights.size()) +
                         " (the others are black: check that the lights fire and the lens is open)");
  }
  // The fit needs pixels with enough unsaturated observations; none at all means the capture is
  // overexposed (or its frames are black) and no material can be measured from it.
  const std::size_t pixels = static_cast<std::size_t>(stack.grid.width) * stack.grid.height;
  std::size_t usable_pixels = 0;
  for (std::size_t i = 0; i < pixels && usable_pixels == 0; ++i) {
    int usable = 0;
    for (const Observation& o : stack.observations) {
      if (!o.flags.empty() && o.flags[i] != 0) continue;
      if (o.rgb.plane(0)[i] + o.rgb.plane(1)[i] + o.rgb.plane(2)[i] > 0.0f) ++usable;
    }
    if (usable >= options.fit.min_observations) ++usable_pixels;
  }
  if (usable_pixels == 0) {
    throw InputError(ManifestPath(prepared), "/frames",
                     "sample frames of side " + side + " where some pixels are lit and unsaturated under at least " +
                         std::to_string(options.fit.min_observations) +
                         " lights; every pixel is saturated or black in too many frames (lower the exposure or the light intensity)");
  }
  return kept_indices;
}

Stack BuildSideStack(const PreparedCapture& prepared, const std::string& side, const StageOptions& options,
                     RunReport* report, const ProgressCallback& progress, const Image& surface_z_mm) {
  const double start = SteadySeconds();
  CalibrationOptions calibration_options = options.calibration;
  calibration_options.side = side;
  Stack stack = BuildStack(prepared.capture, prepared.calibration, calibration_options, progress, surface_z_mm);
  CheckSideStack(prepared, side, options, &stack, report);
  report->steps.push_back({"rectify " + side + (surface_z_mm.empty() ? "" : " on the relief"), true,
                           std::to_string(stack.observations.size()) + " observations on a " +
                               std::to_string(stack.grid.width) + "x" + std::to_string(stack.grid.height) + " grid",
                           SteadySeconds() - start});
  return stack;
}

StepRecord CastShadowStep(const StageOptions& options, double share, bool near, double seconds,
                          double solved_again_share) {
  if (!options.mark_cast_shadows) return {"cast shadows", false, "off: shadows are only dark or outlier data", 0.0};
  char then[96] = "solved again";
  if (solved_again_share >= 0.0) {
    std::snprintf(then, sizeof then, "%.1f %% of the pixels solved again (the others carry no new mark)",
                  100.0 * solved_again_share);
  }
  char detail[200];
  std::snprintf(detail, sizeof detail, "%.2f %% of the observations marked from the %s%s", 100.0 * share,
                near ? "refined heights, every round" : "integrated heights, then ", near ? "" : then);
  return {"cast shadows", true, detail, seconds};
}

StepRecord LevelSideMaps(reconstruction::Levelling levelling, const std::string& side, const Image& valid, Image* height_mm,
                         Image* normal) {
  const std::string name = "level " + side;
  if (levelling == reconstruction::Levelling::kNone) return {name, false, "--level none: the sample's shape is kept", 0.0};
  const double start = SteadySeconds();
  const reconstruction::LevellingResult removed = reconstruction::LevelRelief(levelling, height_mm, normal, valid);
  if (removed.weighted_pixels <= 0.0) return {name, false, "too few valid pixels to fit a " + reconstruction::LevellingName(levelling), 0.0};
  char detail[240];
  std::snprintf(detail, sizeof detail, "%s removed: %.1f um peak to valley, tilt up to %.3f deg; normals %s",
                reconstruction::LevellingName(levelling).c_str(), 1000.0 * removed.peak_to_valley_mm, removed.max_tilt_deg,
                normal ? "turned by the tilt (--level-normals)" : "kept as measured");
  return {name, true, detail, SteadySeconds() - start};
}

SideReconstruction ReconstructSide(Stack* stack, const StageOptions& options, const Image& alpha,
                                   RunReport* report, const ProgressCallback& progress) {
  SideReconstruction out;
  const bool near = HasPointLights(*stack);
  double start = SteadySeconds();
  reconstruction::ShadowMarkingSummary shadows;
  if (options.mark_cast_shadows) {
    out.photometric_stereo = reconstruction::RunPhotometricStereoMarkingShadows(stack, options.photometric_stereo,
                                                                                options.cast_shadows, &shadows, progress);
    out.cast_shadow_share = shadows.counts.share();
    out.cast_shadow_solved_again_share = shadows.solved_again_share;
  } else {
    out.photometric_stereo = reconstruction::RunPhotometricStereo(*stack, options.photometric_stereo, progress);
  }
  const auto& ps = out.photometric_stereo;
  report->steps.push_back({"photometric stereo (" + reconstruction::PsSolverName(options.photometric_stereo.solver) + ")",
                           true,
                           near ? "near point lights, height refined " + std::to_string(ps.near_iterations) + " rounds"
                                : "distant lights",
                           SteadySeconds() - start - shadows.mark_seconds});
  report->steps.push_back(
      CastShadowStep(options, out.cast_shadow_share, near, shadows.mark_seconds, out.cast_shadow_solved_again_share));
  if (!near) {
    report->steps.push_back({"near-light refinement", false,
                             "distant lights: one light direction per frame, no per-pixel light vectors to refine", 0.0});
  }

  IntegrateSide(stack->grid, near, options, alpha, &out, report, progress);
  return out;
}

void IntegrateSide(const MetricGrid& grid, bool near, const StageOptions& options, const Image& alpha,
                   SideReconstruction* side, RunReport* report, const ProgressCallback& progress) {
  SideReconstruction& out = *side;
  const auto& ps = out.photometric_stereo;
  // Valid surface: seen by the camera and not a hole (alpha >= 0.5).
  out.valid = Image(grid.width, grid.height, 1, 1.0f, grid.pitch_mm);
  if (!alpha.empty()) {
    auto v = out.valid.plane(0);
    const auto a = alpha.plane(0);
    for (std::size_t i = 0; i < v.size(); ++i) v[i] = a[i] >= 0.5f ? 1.0f : 0.0f;
  }

  const double start = SteadySeconds();
  if (near && !ps.height_mm.empty() && alpha.empty()) {
    out.height_mm = ps.height_mm;
    report->steps.push_back({"integration", false, "done inside the near-light refinement", 0.0});
  } else {
    reconstruction::IntegrationOptions integration = near ? options.photometric_stereo.integration : options.integration;
    integration.pitch_mm = grid.pitch_mm;
    out.height_mm = reconstruction::IntegrateNormals(ps.normal, out.valid, integration, progress).height_mm;
    report->steps.push_back({"integration (" + reconstruction::IntegratorName(integration.method) + ")", true,
                             alpha.empty() ? "whole grid" : "holes masked out", SteadySeconds() - start});
  }
  out.height_mm.set_pitch_mm(grid.pitch_mm);
}

bool HasPointLights(const Stack& stack) {
  return std::any_of(stack.lights.begin(), stack.lights.end(),
                     [](const LightModel& l) { return l.type == LightType::kPoint; });
}

void ReportObliqueView(const Stack& stack, RunReport* report) {
  if (stack.views.size() >= 2) return;
  report->steps.push_back({"oblique view", false,
                           "one camera: no oblique view, so grazing lobes (sheen) cannot be observed", 0.0});
}

void ReportFitStep(const fitting::FitResult& fit, std::string detail, double seconds, RunReport* report) {
  // Where the time went (fitting::StageTimes), so that a slow fit says which stage made it slow.
  const fitting::StageTimes& t = fit.times;
  char stages[200];
  std::snprintf(stages, sizeof stages,
                "; gather %.1f s, clustering %.1f s, cluster fits %.1f s (observability %.1f s of it), pixels %.1f s",
                t.gather_s, t.clustering_s, t.cluster_fit_s, t.observability_s, t.per_pixel_s);
  detail += stages;
  if (!fit.convergence.all_converged) {
    detail += ", " + std::to_string(fit.convergence.clusters_failed) + " did not converge";
    for (const auto& message : fit.convergence.messages) report->warnings.push_back("fit: " + message);
  }
  report->steps.push_back({"fit", true, detail, seconds});
}

Image FibreTurnsIfFollowed(const Image& normals, const StageOptions& options) {
  return options.follow_fibres ? FibreTurnFromNormals(normals, options.fibre_directions) : Image();
}

fitting::SurfaceGeometry FitGeometry(const Image& normals, const Image& albedo, const Image& height_mm,
                                     const StageOptions& options) {
  return {normals, albedo, height_mm, FibreTurnsIfFollowed(normals, options), Image(), 1};
}

fitting::SurfaceGeometry SideSurface(const SideReconstruction& side) {
  return {side.photometric_stereo.normal, side.photometric_stereo.albedo, side.height_mm, Image(), side.fine_normals,
          side.fine_factor};
}

std::string FacetsDetail(int fine_factor) {
  return ", every photograph fitted as the mixture of the " + std::to_string(fine_factor) + "x finer grid's facets";
}

fitting::FitResult FitSideKeepingModel(const Stack& stack, const SideReconstruction& geometry,
                                       const StageOptions& options, const ProgressCallback& progress,
                                       fitting::ClusterModel* model, std::string* detail) {
  fitting::SurfaceGeometry surface = SideSurface(geometry);
  surface.fibre_turn_deg = FibreTurnsIfFollowed(surface.normals, options);
  fitting::FitResult fit = fitting::FitPrincipled(stack, surface, options.fit, progress, model);
  *detail = std::to_string(fit.clusters.size()) + " clusters";
  if (!surface.fine_normals.empty()) *detail += FacetsDetail(surface.fine_factor);
  return fit;
}

fitting::FitResult FitSide(const Stack& stack, const SideReconstruction& geometry, const StageOptions& options,
                           RunReport* report, const ProgressCallback& progress) {
  ReportObliqueView(stack, report);
  const double start = SteadySeconds();
  fitting::ClusterModel model;
  std::string detail;
  fitting::FitResult fit = FitSideKeepingModel(stack, geometry, options, progress, &model, &detail);
  ReportFitStep(fit, detail, SteadySeconds() - start, report);
  return fit;
}

bool AdoptFittedNormals(fitting::FitResult* fit, const MetricGrid& grid, bool near, const StageOptions& options,
                        SideReconstruction* side, RunReport* report, const ProgressCallback& progress) {
  if (fit->normals.empty()) return false;
  const double start = SteadySeconds();
  side->photometric_stereo.normal = std::move(fit->normals);
  fit->normals = Image();
  side->photometric_stereo.normal.set_pitch_mm(grid.pitch_mm);
  reconstruction::IntegrationOptions integration = near ? options.photometric_stereo.integration : options.integration;
  integration.pitch_mm = grid.pitch_mm;
  side->height_mm = reconstruction::IntegrateNormals(side->photometric_stereo.normal, side->valid, integration, progress)
                        .height_mm;
  side->height_mm.set_pitch_mm(grid.pitch_mm);
  report->steps.push_back({"integration of the fitted normals (" + reconstruction::IntegratorName(integration.method) + ")",
                           true, "normals refined with the fitted model; height integrated again",
                           SteadySeconds() - start});
  return true;
}

Image FitResidualMap(const fitting::FitResult& fit, const Stack& stack, const SideReconstruction& geometry,
                     int max_observations, double* mean_out, std::size_t* pixels_out) {
  const int w = stack.grid.width, h = stack.grid.height;
  Image residual(w, h, 1, 0.0f, stack.grid.pitch_mm);
  std::vector<float> count(static_cast<std::size_t>(w) * h, 0.0f);
  const fitting::SurfaceGeometry surface = SideSurface(geometry);
  const int n = static_cast<int>(stack.observations.size());
  const int used = std::min(n, std::max(1, max_observations));
  for (int k = 0; k < used; ++k) {
    const Observation& observation = stack.observations[static_cast<std::size_t>(k) * n / used];
    const Image render = fitting::RenderFitted(fit, stack, surface, observation);
    for (std::size_t i = 0; i < count.size(); ++i) {
      if (!observation.flags.empty() && observation.flags[i] != 0) continue;
      double data = 0.0, rendered = 0.0, diff = 0.0;
      for (int c = 0; c < 3; ++c) {
        data += observation.rgb.plane(c)[i];
        rendered += render.plane(c)[i];
        diff += std::abs(render.plane(c)[i] - observation.rgb.plane(c)[i]);
      }
      // Relative to the mean of data and render, not to the data alone: a pixel whose data is
      // noise about zero (a gap between yarns in shadow) made |r - d| / d unbounded (a 1 MP twill:
      // one pixel at 31781, the map's mean 0.18 where 0.06 of it came from the rest; a 36 MP one:
      // the mean 121). Now each pixel lies in [0, 2], and where render and data agree within a few
      // per cent the two measures are the same.
      if (!(data > 0.0) || !std::isfinite(diff)) continue;  // a render is >= 0: the mean below is > 0
      residual.plane(0)[i] += static_cast<float>(diff / (0.5 * (data + rendered)));
      count[i] += 1.0f;
    }
  }
  double sum = 0.0;
  std::size_t pixels = 0;
  for (std::size_t i = 0; i < count.size(); ++i) {
    if (count[i] > 0.0f) {
      residual.plane(0)[i] /= count[i];
      sum += residual.plane(0)[i];
      ++pixels;
    }
  }
  if (mean_out) *mean_out = pixels ? sum / static_cast<double>(pixels) : 0.0;
  if (pixels_out) *pixels_out = pixels;
  return residual;
}

}  // namespace u3mscan
