#pragma once
// The pipeline's stages as functions on in-memory data, each timed into a RunReport. `process`,
// `reconstruct`, `fit` and `bench` all run these same functions, so every command measures the
// same code.
//
//   PrepareCapture  open + check the manifest, calibrate (dark/ambient, cameras, lights, flats, colour)
//   BuildSideStack  one side's sample frames on the metric grid (core/stack.h)
//   ReconstructSide photometric stereo (cast shadows marked) + integration -> normal, albedo, confidence, height (mm)
//   FitSide         Principled parameters with Ceres (fitting/principled_fit.h)

#include <filesystem>
#include <string>
#include <vector>

#include "capture/calibrate.h"
#include "capture/capture.h"
#include "core/progress.h"
#include "fitting/principled_fit.h"
#include "pipeline/presets.h"
#include "pipeline/run_report.h"
#include "reconstruction/photometric_stereo.h"
#include "reconstruction/relief_levelling.h"

namespace u3mscan {

namespace fitting {
struct ClusterModel;  // fitting/tiled_fit.h
}  // namespace fitting

struct PreparedCapture {
  Capture capture;
  CalibrationResult calibration;
  std::vector<std::string> sides;  // sides with sample frames, "front" first
};

// Opens and calibrates. Throws InputError for a manifest or frame that does not pass.
PreparedCapture PrepareCapture(const std::filesystem::path& capture_dir, StageOptions& options, RunReport* report,
                               const ProgressCallback& progress = {});

// The checks BuildSideStack makes on a side's stack (or on a sample of its grid): frames without
// signal are left out with a warning; InputError when fewer than three lights are left or no pixel
// has enough lit, unsaturated observations. Returns the indices (into the stack's observations as
// given) of the observations kept, in order.
std::vector<std::size_t> CheckSideStack(const PreparedCapture& prepared, const std::string& side,
                                        const StageOptions& options, Stack* stack, RunReport* report);

// `surface_z_mm`: heights of the relief (BuildStack); empty: the plane of the sample's face.
Stack BuildSideStack(const PreparedCapture& prepared, const std::string& side, const StageOptions& options,
                     RunReport* report, const ProgressCallback& progress = {}, const Image& surface_z_mm = Image());

struct SideReconstruction {
  reconstruction::PhotometricStereoResult photometric_stereo;
  Image height_mm;  // integrated (distant lights) or refined with the near-light model
  Image valid;      // 1 channel: 1 where the surface is data (not a hole, seen by the camera)
  // Share of the (pixel, observation) pairs marked kCastShadow (0 when marking is off).
  double cast_shadow_share = 0.0;
  // Share of the pixels photometric stereo solved again after the marks (-1: not a single second
  // solve, e.g. near-light rounds or marking off).
  double cast_shadow_solved_again_share = -1.0;
  // A side with a tilted view solved on a grid fine_factor times finer (supersampled_reconstruction.h):
  // that grid's unit normals (world frame), which the fit takes as the facets each camera sees in a
  // map pixel (fitting/facet_mixture.h). Empty otherwise.
  Image fine_normals;
  int fine_factor = 1;
};

// Marks the stack's cast shadows (kCastShadow) when options.mark_cast_shadows, so that FitSide and
// FitResidualMap on the same stack leave them out too.
SideReconstruction ReconstructSide(Stack* stack, const StageOptions& options, const Image& alpha,
                                   RunReport* report, const ProgressCallback& progress = {});

// The integration step of ReconstructSide on side->photometric_stereo (grid: the side's whole grid;
// near: the stack has point lights): fills side->valid and side->height_mm.
void IntegrateSide(const MetricGrid& grid, bool near, const StageOptions& options, const Image& alpha,
                   SideReconstruction* side, RunReport* report, const ProgressCallback& progress = {});

// True when one of the stack's lights is a point light (the near-light model and its heights apply).
bool HasPointLights(const Stack& stack);

// The fit's report: the "oblique view" step when `stack` has a single camera (none otherwise), and
// the "fit" step, its `detail` followed by the clusters that did not converge (their messages go
// to the warnings). FitSide, the tiled fit and the fine-grid fit all report this way.
void ReportObliqueView(const Stack& stack, RunReport* report);
void ReportFitStep(const fitting::FitResult& fit, std::string detail, double seconds, RunReport* report);

// Each pixel's turn along the fibres `normals` show (pipeline/fibre_direction.h) with
// options.follow_fibres; empty without.
Image FibreTurnsIfFollowed(const Image& normals, const StageOptions& options);

// The fit's geometry: the given maps and their FibreTurnsIfFollowed.
fitting::SurfaceGeometry FitGeometry(const Image& normals, const Image& albedo, const Image& height_mm,
                                     const StageOptions& options);

// A side's reconstruction as the fit and its re-renders read it: normals, albedo, heights and the
// facets of the finer grid (SideReconstruction::fine_normals); no fibre turns (FitSide adds them).
fitting::SurfaceGeometry SideSurface(const SideReconstruction& side);

// The fit step's words for a fit that takes the facets of a grid `fine_factor` times finer.
std::string FacetsDetail(int fine_factor);

fitting::FitResult FitSide(const Stack& stack, const SideReconstruction& geometry, const StageOptions& options,
                           RunReport* report, const ProgressCallback& progress = {});

// FitSide's fit, not reported: also hands back the cluster model its maps were made from (`model`,
// not null: for a further per-pixel pass with the clusters' lobes, top_view_normals.h) and the fit
// step's words (`detail`, not null; ReportFitStep adds the stage times).
fitting::FitResult FitSideKeepingModel(const Stack& stack, const SideReconstruction& geometry,
                                       const StageOptions& options, const ProgressCallback& progress,
                                       fitting::ClusterModel* model, std::string* detail);

// The report's "cast shadows" step: off, or the share marked and the marking time (seconds).
// solved_again_share: of the pixels, after the marks (< 0: not told).
StepRecord CastShadowStep(const StageOptions& options, double share, bool near, double seconds,
                          double solved_again_share = -1.0);

// After the fit: the fit's refined normals (FitResult::normals; nothing happens when it is empty)
// replace the photometric-stereo normals in `side`, and the height is integrated again from them
// (IntegrateSide's integrator, also for near lights, whose height came from the refinement rounds).
// Photometric stereo's Lambertian normals lean toward a glossy fabric's highlights; the written
// normal map, the height and the residual map then all belong with the fitted parameters
// (docs/fitting.md, "Normal refinement"). The normals are moved out of `fit` (one full-size copy,
// not two: 12 bytes a pixel); returns true when they were adopted.
bool AdoptFittedNormals(fitting::FitResult* fit, const MetricGrid& grid, bool near, const StageOptions& options,
                        SideReconstruction* side, RunReport* report, const ProgressCallback& progress = {});

// The "level" step of a side: its written height levelled (reconstruction::LevelRelief), and its
// normals turned by the removed tilt when `normal` is not null, weighted by `valid` (1 where the
// surface is data; empty = every pixel). The step says what was removed (the surface's peak to
// valley in um and largest tilt) and whether the normals were turned.
StepRecord LevelSideMaps(reconstruction::Levelling levelling, const std::string& side, const Image& valid, Image* height_mm,
                         Image* normal);

// Relative re-rendering residual per pixel, sum_c |render - data| / (0.5 sum_c (render + data)),
// averaged over up to `max_observations` observations spread over the stack (1 channel, in [0, 2];
// 0 where no observation is usable: flagged, or no positive data). `mean_out` receives the mean over usable pixels.
// `pixels_out` (optional) receives the number of usable pixels.
Image FitResidualMap(const fitting::FitResult& fit, const Stack& stack, const SideReconstruction& geometry,
                     int max_observations, double* mean_out, std::size_t* pixels_out = nullptr);


}  // namespace u3mscan
