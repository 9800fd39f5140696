#include "pipeline/side_run.h"

#include <algorithm>
#include <cstdio>
#include <stdexcept>

#include "capture/rectification.h"
#include "capture/stack_builder.h"
#include "core/elapsed.h"
#include "pipeline/alpha_map.h"
#include "pipeline/relief_registration.h"
#include "pipeline/supersampled_reconstruction.h"
#include "pipeline/tiled_side.h"
#include "pipeline/top_view_normals.h"
#include "pipeline/view_parallax.h"

namespace u3mscan {

void SetDecodeCacheBudget(double max_memory_gib, StageOptions* stages) {
  stages->capture.decode_cache_bytes = static_cast<std::size_t>(max_memory_gib * kBytesPerGiB);
}

SideStages StagesForSide(const PreparedCapture& prepared, const std::string& side, const StageOptions& stages) {
  SideStages out{SideViews(prepared, side), false, stages};
  out.tilted_view = NeedsReliefRegistration(out.views);
  if (out.tilted_view) UseTheMostVerticalViewForNormals(out.views, &out.options);
  SetViewParallax(out.views, prepared.calibration, /*rectified_on_relief=*/out.tilted_view, &out.options);
  return out;
}

Image SideAlpha(const PreparedCapture& prepared, const std::string& side, RunReport* report) {
  FrameFilter backlight_filter;
  backlight_filter.role = FrameRole::kBacklight;
  backlight_filter.side = side;
  const auto backlight = prepared.capture.Frames(backlight_filter);
  if (backlight.empty()) {
    report->steps.push_back({"alpha " + side, false, "no backlight frame", 0.0});
    return Image();
  }
  const double start = SteadySeconds();
  const std::size_t index = backlight.front();
  const CameraCalibration* camera = prepared.calibration.FindCamera(prepared.capture.frame(index).camera);
  if (!camera) throw std::logic_error("calibration lacks camera " + prepared.capture.frame(index).camera);
  const MetricGrid& grid = prepared.calibration.grid;
  const RectificationMap map = BuildRectificationMap(camera->model, grid, prepared.calibration.surface_z_mm);
  const RectifiedFrame rectified = Rectify(prepared.capture.LoadFrame(index), map);
  AlphaEstimate estimate = AlphaFromBacklight(rectified.rgb, rectified.flags);
  report->steps.push_back({"alpha " + side, true,
                           estimate.alpha.empty() ? estimate.note
                                                  : "holes cover " + std::to_string(100.0 * estimate.hole_fraction) + " %",
                           SteadySeconds() - start});
  return std::move(estimate.alpha);
}

SideRun RunSide(const PreparedCapture& prepared, const std::string& side, const StageOptions& stages,
                const SideRunOptions& options, RunReport* report, const ProgressCallback& progress) {
  SideRun run;
  run.alpha = SideAlpha(prepared, side, report);
  const Image& alpha = run.alpha;

  // The whole side at once when its stack fits the budget, else band by band (tiled_side.h).
  const Manifest& manifest = prepared.capture.manifest();
  const std::vector<std::size_t> side_frames = SideSampleFrames(manifest, side);
  bool flats = false;
  for (std::size_t index : side_frames) {
    const FrameSpec& spec = manifest.frames[index];
    flats = flats || (spec.light && prepared.calibration.FindFlat(spec.camera, *spec.light, side));
  }
  // A tilted view: its frames registered on the relief (one band) and the normals taken from the
  // most vertical view; otherwise the heights along the camera's rays (StagesForSide).
  const SideStages decided = StagesForSide(prepared, side, stages);
  const StageOptions& side_stages = decided.options;
  const Stack& views = decided.views;
  const bool tilted_view = decided.tilted_view;
  // --ps-supersample: photometric stereo on a grid k times finer; the bands are planned so that
  // each one's fine stack fits the budget (one band when the whole fine stack does).
  const int k = options.ps_supersample == 0 ? PsSupersampleForCameras(prepared.calibration, views)
                                            : std::clamp(options.ps_supersample, 1, kMaxPsSupersample);
  run.ps_supersample = k;
  run.plan = PlanTiles(prepared.calibration.grid, static_cast<int>(side_frames.size()), flats,
                       options.max_memory_gib * kBytesPerGiB, k);
  report->options["ps_supersample_" + side] = k;
  if (run.plan.bands == 1) {
    Stack& stack = run.stack;
    stack = BuildSideStack(prepared, side, stages, report, progress);
    std::vector<Observation> held_out;
    if (!options.hold_out_lights.empty()) held_out = TakeHeldOutObservations(&stack, options.hold_out_lights);
    if (tilted_view) {
      stack = BuildSideStackOnRelief(prepared, side, stages, alpha, std::move(stack), report, progress);
      if (!options.hold_out_lights.empty()) held_out = TakeHeldOutObservations(&stack, options.hold_out_lights);
    }
    FineReconstruction fine;
    run.reconstruction = ReconstructSideSupersampled(prepared, side, k, &stack, side_stages, alpha, report, progress, &fine);
    Image fine_height;
    run.fit = RefinesTopViewNormals(side_stages, k)
                  ? FitSideRefiningTopViewNormals(stack, run.reconstruction, std::move(fine), side_stages, report,
                                                  progress, &fine_height)
                  : FitSideWithFineNormals(stack, run.reconstruction, std::move(fine), side_stages, report, progress,
                                           &fine_height);
    const bool near = HasPointLights(stack);
    run.fitted_normals =
        fine_height.empty()
            ? AdoptFittedNormals(&run.fit, stack.grid, near, side_stages, &run.reconstruction, report, progress)
            : AdoptFineFittedNormals(&run.fit, std::move(fine_height), &run.reconstruction, report,
                                     RefinesTopViewNormals(side_stages, k));
    if (tilted_view && !run.fitted_normals) report->steps.push_back(TiltedViewNormalsStep());
    run.residual = FitResidualMap(run.fit, stack, run.reconstruction, kResidualObservations, &run.residual_mean);
    if (!held_out.empty()) run.held_out = CheckHeldOutLights(run.fit, stack, run.reconstruction, std::move(held_out), stages);
  } else {
    TiledSide tiled = ProcessSideTiled(prepared, side, side_stages, run.plan, alpha, kResidualObservations,
                                       options.hold_out_lights, report, progress);
    run.held_out = std::move(tiled.held_out);
    // Registered on the relief in bands.
    if (tilted_view && !tiled.fitted_normals) report->steps.push_back(TiltedViewNormalsStep());
    run.stack = std::move(tiled.sample);
    run.reconstruction = std::move(tiled.reconstruction);
    run.fit = std::move(tiled.fit);
    run.residual = std::move(tiled.residual);
    run.residual_mean = tiled.residual_mean;
    run.fitted_normals = tiled.fitted_normals;
  }
  if (run.held_out) {
    char detail[120];
    std::snprintf(detail, sizeof detail, "%zu light(s) left out of the fit: relative RMSE %.2f %% against their photographs",
                  run.held_out->lights.size(), 100.0 * run.held_out->relative_rmse);
    report->steps.push_back({"held-out lights " + side, true, detail, run.held_out->seconds});
  }
  // Frames kept whole by their header (RAW, PNG, JPEG, compressed TIFF) that the decode cache had no
  // room for are read by region on every band read since (capture/capture.h): say so, as a larger
  // --max-memory keeps them whole. `process` empties the cache and its refusals after each side
  // (Capture::ReleaseCache), so the count is this side's.
  if (const std::size_t by_region = prepared.capture.frames_read_by_region(); by_region > 0) {
    char detail[240];
    std::snprintf(detail, sizeof detail,
                  "%.2f GiB of frames kept whole (--max-memory %.3g); %zu frame(s) found no room and are read by "
                  "region on every band read",
                  static_cast<double>(prepared.capture.cached_bytes()) / kBytesPerGiB, options.max_memory_gib, by_region);
    report->steps.push_back({"decode cache " + side, true, detail, 0.0});
  }
  report->options["tiles_" + side] = {{"bands", run.plan.bands}, {"band_rows", run.plan.band_rows},
                                      {"fit_sample_step", run.plan.sample_step},
                                      {"stack_gib", run.plan.whole_stack_bytes / kBytesPerGiB}};
  return run;
}

}  // namespace u3mscan
