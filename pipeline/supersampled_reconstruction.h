#pragma once
// Photometric stereo on a grid k times finer than the maps' (what a camera at k times the maps'
// dpi resolves), its normals averaged onto the maps' grid (`--ps-supersample K`).
//
// Why: a map pixel of a woven fabric holds yarn flanks of several colours and slopes. Solved on the
// maps' grid, photometric stereo sees their shading summed and returns the albedo-weighted normal
// (a darker yarn or gap weighs less) bent by the lobes of facets it cannot tell apart. On the
// finer grid each solve covers fewer facets, and the plain mean of the fine unit normals over a
// map pixel is close to its area-average normal: the normal that integrates to its height, and the
// truth the synthetic scanner writes. Measured with the pixel-area probe on plain at 300 dpi, on
// the grid: least squares on a Lambertian grey weave 0.06 deg, with the weave's colours 1.37 deg,
// with its lobes 1.65 deg (docs/reconstruction.md, "Photometric stereo at the camera's resolution").
//
// The fit's clusters run on the fine grid too (FitSideWithFineNormals), its written maps on the
// maps' grid (its stack, `stack` below), with these normals.

#include <string>

#include "capture/calibrate.h"
#include "core/image.h"
#include "core/stack.h"
#include "fitting/principled_fit.h"
#include "pipeline/fine_grid.h"
#include "pipeline/run_report.h"
#include "pipeline/stages.h"

namespace u3mscan {

// Largest supersampling factor asked for (`--ps-supersample 5`): 5 x 5 fine solves per map pixel.
inline constexpr int kMaxPsSupersample = 5;

// The default (0: as fine as the camera resolves) takes the floor of the top camera's pixels per
// map pixel R up to 3, and from R = 4 on one fine pixel more than camera pixels: 5 x 5 (a
// 36-megapixel camera over a 15 cm sample photographs at about 1200 dpi, four times 300 dpi maps:
// 25 times the maps' stack, processed in bands). At 4x rather than 3x from a 1200 dpi camera
// (docs/reconstruction.md, "Photometric stereo at the camera's resolution"): plain 1.110 -> 0.918
// deg, twill 1.578 -> 1.336.
inline constexpr int kMaxAutoPsSupersample = 5;
// The camera's pixels per map pixel from which the default spreads the phases (below).
inline constexpr int kSpreadPhasesFromRatio = 4;

// The default factor for a top camera with `camera_px_per_map_px` pixels per map pixel (R): its
// floor (a camera at 2.98 px per map px, its dpi rounded, counts as 3) within [1, 3]; 5 from
// kSpreadPhasesFromRatio on; 1 when R is not positive.
//
// At K = R every fine pixel of a region is read at the same sub-pixel phase between camera pixels,
// and the normals carry a bias that depends on that phase; as the phase drifts across the map
// (the camera's pitch on the sample's face is not exactly the grid's) a small map's height gets a
// bowl of either sign (twill at 1200 dpi, 192 px maps at 300 dpi, K = 4: height 11.3, 6.8 and
// 5.6 % of the range on seeds 1 to 3). K = 5 (one fine pixel more than camera pixels, their
// phases spread) takes the bowl out: with the fine pixels placed on the plan (plan_placement.h),
// twill 18.9 -> 3.7 %, plain 3.2 -> 1.6 %, and a 9 MP plain 0.947 -> 0.881 deg, 7.9 -> 5.1 %, in
// 1.48 times the run time (docs/reconstruction.md, "The camera's own pitch"). At R = 3, K = 4
// gained nothing (three seeds), so the rule starts at 4. `--ps-supersample 4` keeps the camera's
// own grid, for a quicker run.
int PsSupersampleForCameraRatio(double camera_px_per_map_px);

// The factor a side's cameras support: PsSupersampleForCameraRatio of its most vertical view's
// camera pixels per map pixel (at the grid's centre, on the face's plane). `views`: the side's
// views (SideViews, or its stack).
int PsSupersampleForCameras(const CalibrationResult& calibration, const Stack& views);

// The factor a run without bands uses (`reconstruct`; `process` plans bands on the finer grid
// instead, PlanTiles' fine_factor): `requested` (0: PsSupersampleForCameras of `views`; else
// 1..kMaxPsSupersample), lowered until the fine stack of `observations` frames fits `budget_bytes` in one band
// (PlanTiles; a scan that needs bands on the maps' grid gets 1). `why` (when not null) says what
// lowered it, or is cleared.
int ChoosePsSupersample(int requested, const CalibrationResult& calibration, const Stack& views, int observations,
                        bool flats, double budget_bytes, std::string* why);

// ReconstructSide with photometric stereo on RefineGrid(calibration grid, k). `stack` is the side's
// stack on the maps' grid as the fit will use it: only the frames it holds (by camera and light:
// held-out lights and frames the side's checks left out stay out) are read again onto the fine
// grid. The fine stack's flats are the maps' irradiance, interpolated; `alpha` (maps' grid) is
// taken to the fine one by nearest pixel. With options.photometric_stereo.view set (a tilted view:
// relief_registration.h) only that view's frames are read, on the face's plane (the top view
// moves by hundredths of a pixel on the relief). On the maps' grid: normals = normalised mean of the k x k
// fine unit normals, albedo and confidence their means, condition number their largest; near lights'
// heights the mean of the fine heights. The height is then integrated on the maps' grid as
// ReconstructSide does, and `stack`'s cast shadows are marked from it (when
// options.mark_cast_shadows). Reports the photometric stereo step (named with the factor), the
// cast shadows and the integration. k = 1 is ReconstructSide. Throws like BuildStack.
// What the fit needs of the fine grid to refine the normals there (FitSideWithFineNormals).
struct FineReconstruction {
  int k = 1;                // 1: nothing below is set
  Stack stack;              // the fine stack: the maps' observations in their order (a tilted view: its top view's)
  SideReconstruction side;  // photometric stereo and heights on the fine grid
};

// `keep_fine` (not null, k > 1, and the fine stack holds every observation of `stack`, i.e. no
// restriction to one view, or it holds the one view's and RefinesTopViewNormals: top_view_normals.h):
// the fine stack and reconstruction are moved there for the fit.
SideReconstruction ReconstructSideSupersampled(const PreparedCapture& prepared, const std::string& side, int k,
                                               Stack* stack, const StageOptions& options, const Image& alpha,
                                               RunReport* report, const ProgressCallback& progress = {},
                                               FineReconstruction* keep_fine = nullptr);

// FitSide, and with `fine` (k > 1) and options.fit.refine_pixel_normals: the clusters fitted on the
// fine stack and normals (options.fit_clusters_on_fine_grid; there a pixel holds fewer yarn facets,
// and the one-normal-per-pixel model reads a woven fabric's specular lobe less weak: plain at 3x,
// specular 0.25 -> 0.37 for 0.5, velvet's re-render 3.6 -> 2.4 %; docs/fitting.md, "Clusters on the
// finer grid"; tiled_side.cc does the same on a sample of the fine bands), the per-pixel step on
// the maps' grid, and the fitted normals refined on the fine grid: each fine pixel with its nearest
// cluster's parameters (fitting/tiled_fit.h FitPixelRows on the fine stack), their unit normals
// averaged onto the maps' grid. Refined on the maps' grid they would lean back to the
// albedo-weighted normal of the whole pixel (plain at 3x: 1.34 deg from photometric stereo at 3x,
// 1.94 after a refinement on the maps' grid). The refined fine normals are also integrated on the
// fine grid, and `fine_height_mm` (not null) gets, per map pixel, the mean of its fine heights (the
// truth's own definition of a pixel's height, which integrating normals on the maps' grid misses at
// the yarn steps) for the detail, and for the wavelengths longer than a few map pixels (the fine
// heights drift there) the maps' grid integration of the same fine normals' average, the normal
// map written (IntegrateFineRefinedNormals says why not the normals refined on the maps' grid).
// Left empty when the normals were not refined on the fine grid. The same fine step gives the base colour
// (options.base_colour_from_fine_grid, fine_colour.h): each map pixel the mean of its fitted fine
// pixels'. `fine` is released before returning.
fitting::FitResult FitSideWithFineNormals(const Stack& stack, const SideReconstruction& geometry, FineReconstruction fine,
                                          const StageOptions& options, RunReport* report,
                                          const ProgressCallback& progress = {}, Image* fine_height_mm = nullptr);

// The height of normals refined on the fine grid (`fine_normals`, its `fine_valid`; consumed), from
// them alone: integrated on the fine grid for the detail, and their average onto the maps
// (AverageNormalsOntoMaps weighted by `fine_weights`, SurfaceAreaWeights of `fine_normals`, which
// the caller has already made; empty: all 1) integrated on the maps' grid (`maps_valid`, pitch
// `maps_pitch_mm` = k fine pixels) for the long wavelengths; joined by HeightFromFineAndMapsGrids,
// the fine heights weighted by `fine_weights`. Both integrations are AdoptFittedNormals' (`near`:
// the near-light one). The long wavelengths used to come from the normals the fit refined on the
// maps' grid: one normal fitted to a map pixel's photographs is its facets' mean as the camera sees
// them, which leans toward the camera by about the facets' slope covariance times the ray's lean,
// a bowl centred under the camera (docs/reconstruction.md, "Where the bowl came from").
// With `placement` on (plan_placement.h), both the average and the fine heights' block means put
// each fine pixel where its surface point lies in plan, and the average, being on the plan, is
// integrated without the view's parallax. `maps_normals` (not null) gets that average, the normal
// map the caller writes, so that it is not made twice. `long_wavelengths_mm` (not null: heights on
// the maps' grid) replaces the average's integration for the long wavelengths (a tilted capture's
// top-view refinement keeps photometric stereo's there, top_view_normals.h). FitSideWithFineNormals'
// height, and the banded path's.
Image IntegrateFineRefinedNormals(Image fine_normals, const Image& fine_valid, const Image& fine_weights,
                                  const Image& maps_valid, int k, double maps_pitch_mm, bool near,
                                  const StageOptions& options, const ProgressCallback& progress = {},
                                  const PlanPlacement& placement = PlanPlacement(), Image* maps_normals = nullptr,
                                  const Image* long_wavelengths_mm = nullptr);

// AdoptFittedNormals with the height from the fine grid (FitSideWithFineNormals' `fine_height_mm`):
// the fit's normals replace the reconstruction's and `fine_height_mm` its height; reports the
// step, which says so when the normals were refined against the top view alone and the height's
// long wavelengths are photometric stereo's (`top_view`, top_view_normals.h). Returns false
// (nothing done) when the fit has no normals or the height is empty.
bool AdoptFineFittedNormals(fitting::FitResult* fit, Image fine_height_mm, SideReconstruction* side, RunReport* report,
                            bool top_view = false);

}  // namespace u3mscan
