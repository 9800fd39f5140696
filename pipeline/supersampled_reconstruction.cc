#include "pipeline/supersampled_reconstruction.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <set>
#include <vector>
#include <utility>

#include "core/elapsed.h"
#include "capture/stack_builder.h"
#include "fitting/tiled_fit.h"
#include "pipeline/fine_colour.h"
#include "pipeline/fine_grid.h"
#include "pipeline/relief_registration.h"
#include "pipeline/tiles.h"
#include "pipeline/top_view_normals.h"
#include "reconstruction/cast_shadows.h"
#include "reconstruction/normal_integration.h"

namespace u3mscan {
namespace {

// A camera at 2.98 px per map px (its dpi rounded) supports 3: the floor is taken this much above.
constexpr double kFactorSlack = 0.05;

// The side's sample frames (manifest indices) of the (camera, light) pairs `stack` holds, and of
// those only view `only_view`'s camera when it is >= 0.
std::vector<std::size_t> FramesOf(const Manifest& manifest, const std::string& side, const Stack& stack, int only_view) {
  std::set<std::pair<std::string, std::string>> kept;
  for (const Observation& o : stack.observations) {
    kept.insert({stack.views.at(static_cast<std::size_t>(o.view)).camera_id, stack.lights.at(static_cast<std::size_t>(o.light)).id});
  }
  std::vector<std::size_t> frames;
  for (std::size_t index : SideSampleFrames(manifest, side)) {
    const FrameSpec& spec = manifest.frames[index];
    if (!spec.light || !kept.count({spec.camera, *spec.light})) continue;
    if (only_view >= 0 && spec.camera != stack.views.at(static_cast<std::size_t>(only_view)).camera_id) continue;
    frames.push_back(index);
  }
  return frames;
}

}  // namespace

int PsSupersampleForCameraRatio(double camera_px_per_map_px) {
  if (!(camera_px_per_map_px > 0.0)) return 1;  // NaN too
  // Clamped as a double: the cast of a huge ratio would overflow.
  const int floor = static_cast<int>(std::clamp(std::floor(camera_px_per_map_px + kFactorSlack), 1.0,
                                                static_cast<double>(kSpreadPhasesFromRatio)));
  return floor >= kSpreadPhasesFromRatio ? kMaxAutoPsSupersample : floor;
}

int PsSupersampleForCameras(const CalibrationResult& calibration, const Stack& views) {
  const int top = MostVerticalView(views);
  const CameraCalibration* camera =
      top < 0 ? nullptr : calibration.FindCamera(views.views.at(static_cast<std::size_t>(top)).camera_id);
  if (!camera) return 1;
  const MetricGrid& grid = calibration.grid;
  const double pitch =
      camera->model.PitchOnPlaneMm(grid.PixelCentreInWorld(grid.width / 2, grid.height / 2, calibration.surface_z_mm));
  if (!(pitch > 0.0)) return 1;
  return PsSupersampleForCameraRatio(grid.pitch_mm / pitch);
}

int ChoosePsSupersample(int requested, const CalibrationResult& calibration, const Stack& views, int observations,
                        bool flats, double budget_bytes, std::string* why) {
  if (why) why->clear();
  int k = requested == 0 ? PsSupersampleForCameras(calibration, views) : std::clamp(requested, 1, kMaxPsSupersample);
  const int wanted = k;
  while (k > 1 && PlanTiles(RefineGrid(calibration.grid, k), observations, flats, budget_bytes).bands > 1) --k;
  if (why && k < wanted) {
    *why = std::to_string(wanted) + "x finer would not fit the memory budget in one band (--max-memory): " +
           (k > 1 ? std::to_string(k) + "x" : "on the maps' grid");
  }
  return k;
}

SideReconstruction ReconstructSideSupersampled(const PreparedCapture& prepared, const std::string& side, int k,
                                               Stack* stack, const StageOptions& options, const Image& alpha,
                                               RunReport* report, const ProgressCallback& progress,
                                               FineReconstruction* keep_fine) {
  if (keep_fine) *keep_fine = FineReconstruction();
  if (k <= 1) return ReconstructSide(stack, options, alpha, report, progress);
  const MetricGrid& grid = stack->grid;
  double start = SteadySeconds();
  const CalibrationResult fine_calibration = FineCalibration(prepared.calibration, k);
  CalibrationOptions calibration_options = options.calibration;
  calibration_options.side = side;
  const std::vector<std::size_t> frames =
      FramesOf(prepared.capture.manifest(), side, *stack, options.photometric_stereo.view);
  Stack fine = BuildStackRows(prepared.capture, fine_calibration, calibration_options, frames, 0,
                              fine_calibration.grid.height, progress);
  // The fine stack's views are numbered by its own frames: a restriction to one view follows its camera.
  StageOptions fine_options = options;
  if (options.photometric_stereo.view >= 0) {
    const std::string& camera = stack->views.at(static_cast<std::size_t>(options.photometric_stereo.view)).camera_id;
    fine_options.photometric_stereo.view = -1;
    for (std::size_t v = 0; v < fine.views.size(); ++v) {
      if (fine.views[v].camera_id == camera) fine_options.photometric_stereo.view = static_cast<int>(v);
    }
  }
  report->steps.push_back({"rectify " + side + " at " + std::to_string(k) + "x", true,
                           std::to_string(fine.observations.size()) + " observations on a " +
                               std::to_string(fine.grid.width) + "x" + std::to_string(fine.grid.height) +
                               " grid, for photometric stereo",
                           SteadySeconds() - start});

  // The fine reconstruction's own steps describe a grid the run does not write; one step says what ran.
  RunReport fine_report;
  SideReconstruction fine_side =
      ReconstructSide(&fine, fine_options, alpha.empty() ? Image() : UpsampleNearest(alpha, k), &fine_report, progress);
  const bool every_observation = fine.observations.size() == stack->observations.size();
  const reconstruction::PhotometricStereoResult& f = fine_side.photometric_stereo;
  start = SteadySeconds();
  SideReconstruction out;
  // Each fine pixel put where its surface point lies in plan, by the fine heights, as the fit's
  // refined normals are (FitSideWithFineNormals): the maps' normals, albedo and heights, and so the
  // normals `reconstruct` writes and those the maps' fit starts from. Along the integration's rays
  // only: a tilted capture's average stays where the top view's rays met the plane, as its bands'
  // does (tiled_side.cc), and only its written normals, the top view's refined ones, are placed
  // (top_view_normals.h; placed here too, the fast preset's clusters on a 192 px velvet moved
  // enough to turn that refinement from 0.02 deg better than photometric stereo to 0.05 worse).
  const PlanPlacement placement = options.place_fine_pixels_on_plan
                                      ? PlanPlacement(fine_side.height_mm, fine_side.valid, options.integration.parallax, k)
                                      : PlanPlacement();
  out.photometric_stereo = AveragePhotometricStereoOntoMaps(f, k, grid.pitch_mm, options.integration.parallax, 0, placement);
  double solve_seconds = 0.0;
  for (const StepRecord& s : fine_report.steps) {
    if (s.name.rfind("photometric stereo", 0) == 0 || s.name == "cast shadows") solve_seconds += s.seconds;
  }
  const bool near = HasPointLights(*stack);
  char detail[320];
  std::snprintf(detail, sizeof detail,
                "on the %dx%d grid (%d x %d solves per map pixel), %s; the unit normals averaged onto the maps' grid%s",
                fine_side.photometric_stereo.normal.width(), fine_side.photometric_stereo.normal.height(), k, k,
                near ? ("near point lights, height refined " + std::to_string(f.near_iterations) + " rounds").c_str()
                     : "distant lights",
                PlacementDetail(placement, fine.grid.pitch_mm).c_str());
  report->steps.push_back({"photometric stereo (" + reconstruction::PsSolverName(options.photometric_stereo.solver) + ", " +
                               std::to_string(k) + "x finer grid)",
                           true, detail, solve_seconds + (SteadySeconds() - start)});
  if (!near) {
    report->steps.push_back({"near-light refinement", false,
                             "distant lights: one light direction per frame, no per-pixel light vectors to refine", 0.0});
  }
  // Placed on the plan, the average's slopes are the surface's along the grid: no parallax.
  StageOptions maps_options = options;
  if (placement.enabled()) {
    maps_options.integration.parallax.enabled = false;
    maps_options.photometric_stereo.integration.parallax.enabled = false;
  }
  IntegrateSide(grid, near, maps_options, alpha, &out, report, progress);
  // The fit's stack leaves out what the heights shadow, as ReconstructSide's does. The share
  // reported is photometric stereo's, on the fine grid, as the banded path reports it: the maps'
  // heights are too smooth to shadow a yarn's wall (plain at 3x: 0.02 % of the maps' observations
  // against 13.7 % of the fine ones).
  start = SteadySeconds();
  if (options.mark_cast_shadows) {
    reconstruction::MarkCastShadows(out.height_mm, stack, options.cast_shadows);
    out.cast_shadow_share = fine_side.cast_shadow_share;
    out.cast_shadow_solved_again_share = fine_side.cast_shadow_solved_again_share;
  }
  report->steps.push_back(
      CastShadowStep(options, out.cast_shadow_share, near, SteadySeconds() - start, out.cast_shadow_solved_again_share));
  if (options.photometric_stereo.view >= 0 && NeedsReliefRegistration(*stack) && options.fit_facets) {
    // The fine solves read the most vertical view alone and the fit stays on the maps' grid: it
    // takes their normals as the facets each camera sees in a map pixel (fitting/facet_mixture.h;
    // docs/fitting.md, "Facets of the finer grid").
    out.fine_normals = f.normal;
    out.fine_factor = k;
  }
  if (keep_fine && (every_observation || RefinesTopViewNormals(options, k))) {
    keep_fine->k = k;
    keep_fine->stack = std::move(fine);
    keep_fine->side = std::move(fine_side);
  }
  return out;
}

Image IntegrateFineRefinedNormals(Image fine_normals, const Image& fine_valid, const Image& fine_weights,
                                  const Image& maps_valid, int k, double maps_pitch_mm, bool near,
                                  const StageOptions& options, const ProgressCallback& progress,
                                  const PlanPlacement& placement, Image* maps_normals,
                                  const Image* long_wavelengths_mm) {
  // AdoptFittedNormals' integrator (also for near lights), on each grid.
  reconstruction::IntegrationOptions integration = near ? options.photometric_stereo.integration : options.integration;
  integration.pitch_mm = maps_pitch_mm / k;
  fine_normals.set_pitch_mm(integration.pitch_mm);
  Image average = AverageNormalsOntoMaps(fine_normals, k, maps_pitch_mm, fine_weights, placement);
  const Image fine_height = reconstruction::IntegrateNormals(fine_normals, fine_valid, integration, progress).height_mm;
  fine_normals = Image();
  integration.pitch_mm = maps_pitch_mm;
  // Placed on the plan, the average's slopes are the surface's along the grid: no parallax.
  if (placement.enabled()) integration.parallax.enabled = false;
  Image maps_height;
  if (!long_wavelengths_mm) maps_height = reconstruction::IntegrateNormals(average, maps_valid, integration, progress).height_mm;
  if (maps_normals) *maps_normals = std::move(average);
  // Each fine height is the height of the point seen there: weighted by its share of the surface.
  return HeightFromFineAndMapsGrids(fine_height, long_wavelengths_mm ? *long_wavelengths_mm : maps_height, k,
                                    fine_weights, placement);
}

fitting::FitResult FitSideWithFineNormals(const Stack& stack, const SideReconstruction& geometry, FineReconstruction fine,
                                          const StageOptions& options, RunReport* report,
                                          const ProgressCallback& progress, Image* fine_height_mm) {
  if (fine_height_mm) *fine_height_mm = Image();
  if (fine.k <= 1 || !options.fit.refine_pixel_normals) return FitSide(stack, geometry, options, report, progress);
  ReportObliqueView(stack, report);
  const double start = SteadySeconds();
  const int k = fine.k;
  const fitting::SurfaceGeometry fine_surface = FitGeometry(
      fine.side.photometric_stereo.normal, fine.side.photometric_stereo.albedo, fine.side.height_mm, options);
  // The maps' grid's fibre turns are the fine grid's, averaged (fibre_direction.h).
  const fitting::SurfaceGeometry surface{geometry.photometric_stereo.normal, geometry.photometric_stereo.albedo,
                                         geometry.height_mm,
                                         fine_surface.fibre_turn_deg.empty()
                                             ? Image()
                                             : AverageTurnsOntoMaps(fine_surface.fibre_turn_deg, k, stack.grid.pitch_mm),
                                         Image(), 1};
  // FitPrincipled's stages (tiled_fit.h): the clusters on the fine grid (its stack holds the maps'
  // observations in the same order, so the model serves both grids), then the per-pixel step on the
  // maps' grid for the written maps and once more on the fine grid for the normals.
  const bool clusters_on_fine_grid = options.fit_clusters_on_fine_grid;
  const fitting::ClusterModel model = clusters_on_fine_grid
                                          ? fitting::FitClusterModel(fine.stack, fine_surface, options.fit, progress)
                                          : fitting::FitClusterModel(stack, surface, options.fit, progress);
  fitting::FitResult fit = fitting::StartPixelMaps(model, stack.grid);
  fitting::PixelTally tally;
  fitting::FitPixelRows(model, stack, surface, 0, &fit, &tally, progress);
  fitting::FinishPixelMaps(model, tally, &fit);
  const double fine_start = SteadySeconds();
  std::string placed;  // what the plan placement moved, for the report
  {
    fitting::FitResult fine_fit = fitting::StartPixelMaps(model, fine.stack.grid);
    fitting::PixelTally fine_tally;
    fitting::FitPixelRows(model, fine.stack, fine_surface, 0, &fine_fit, &fine_tally, progress);
    // Each fine pixel weighted by its share of the surface seen along the camera's rays (fine_grid.h),
    // and put where its surface point lies in plan (plan_placement.h), by the fine heights.
    const Image weights = SurfaceAreaWeights(fine_fit.normals, options.integration.parallax);
    const PlanPlacement placement = options.place_fine_pixels_on_plan
                                        ? PlanPlacement(fine.side.height_mm, fine.side.valid, options.placement_parallax, k)
                                        : PlanPlacement();
    placed = PlacementDetail(placement, fine.stack.grid.pitch_mm);
    // The base colour from the fine pixels' own (fine_colour.h: a map pixel's spread of facet
    // normals reads as a darker colour on the maps' grid).
    if (options.base_colour_from_fine_grid) {
      FineColourAverage colour(stack.grid.width, stack.grid.height, k);
      colour.Add(fine_fit.base_color, fine_fit.cluster_id, 0, weights, placement);
      colour.ApplyTo(fit.cluster_id, &fit.base_color);
    }
    if (!fine_fit.normals.empty()) {
      if (fine_height_mm) {
        *fine_height_mm = IntegrateFineRefinedNormals(std::move(fine_fit.normals), fine.side.valid, weights,
                                                      geometry.valid, k, stack.grid.pitch_mm, HasPointLights(stack),
                                                      options, progress, placement, &fit.normals);
      } else {
        fit.normals = AverageNormalsOntoMaps(fine_fit.normals, k, stack.grid.pitch_mm, weights, placement);
      }
    }
  }
  const double fine_seconds = SteadySeconds() - fine_start;
  fine = FineReconstruction();
  fit.times.total_s = SteadySeconds() - start;
  char seconds[64];
  std::snprintf(seconds, sizeof seconds, " (%.2f s of it)", fine_seconds);
  ReportFitStep(fit,
                std::to_string(fit.clusters.size()) + " clusters fitted on the " +
                    (clusters_on_fine_grid ? std::to_string(k) + "x finer grid" : std::string("maps' grid")) +
                    "; normals refined on the " + std::to_string(k) + "x finer grid" + seconds + placed,
                SteadySeconds() - start, report);
  return fit;
}

bool AdoptFineFittedNormals(fitting::FitResult* fit, Image fine_height_mm, SideReconstruction* side, RunReport* report,
                            bool top_view) {
  if (fit->normals.empty() || fine_height_mm.empty()) return false;
  side->photometric_stereo.normal = std::move(fit->normals);
  fit->normals = Image();
  side->height_mm = std::move(fine_height_mm);
  report->steps.push_back({"integration of the fitted normals (on the finer grid)", true,
                           top_view ? "normals refined against the top view with the fitted model on the finer grid; "
                                      "height: its detail integrated there, each map pixel the mean of its fine "
                                      "heights, its long wavelengths photometric stereo's (time in the fit's step)"
                                    : "normals refined with the fitted model on the finer grid; height integrated "
                                      "there, each map pixel the mean of its fine heights (time in the fit's step)",
                           0.0});
  return true;
}

}  // namespace u3mscan
