#pragma once
// The finer grid that photometric stereo runs on with `--ps-supersample K`
// (supersampled_reconstruction.h for one band, tiled_side.h for bands): the grid itself, its
// calibration, and the resampling between it and the maps' grid. Fine pixel (k col + i, k row + j)
// is the (i, j) part of map pixel (col, row).

#include "capture/calibrate.h"
#include "core/image.h"
#include "pipeline/plan_placement.h"
#include "reconstruction/normal_integration.h"
#include "reconstruction/photometric_stereo.h"

namespace u3mscan {

// The grid over the same region with k x k pixels for each of `grid`'s (pitch / k).
MetricGrid RefineGrid(const MetricGrid& grid, int k);

// The same cameras, lights and corrections on RefineGrid(calibration.grid, k); the flats'
// irradiance interpolated onto it.
CalibrationResult FineCalibration(const CalibrationResult& calibration, int k);

// Onto the fine grid: bilinear at the fine pixels' centres, edges clamped (smooth quantities:
// heights, irradiance); nearest (masks: alpha, valid). Pitch: the image's / k.
Image UpsampleLinear(const Image& coarse, int k);
Image UpsampleNearest(const Image& coarse, int k);

// The first plane of `in` blurred by a Gaussian of sigma `sigma_px` pixels, 3 sigma either side,
// edges mirrored (1 plane out).
Image GaussianBlurPlane(const Image& in, double sigma_px);

// Back onto the maps' grid (pitch `pitch_mm`): each k x k block's mean, and its largest value.
Image BlockMean(const Image& fine, int k, double pitch_mm);
Image BlockMax(const Image& fine, int k, double pitch_mm);

// Each fine pixel's share of the surface's plan: 1 / ParallaxStretch of its normal's slope
// (reconstruction/normal_integration.h); empty (every weight 1) when the parallax is off or there
// are no normals. A grid point shows the surface point on its camera ray, so a facet that faces
// the camera covers more grid pixels than its plan's area (1 - s . t times it), and a plain mean
// over the grid pixels leans toward the camera; these weights make it the mean over the surface,
// as the truth's maps are defined (docs/reconstruction.md, "Averaging the finer grid along the
// camera's rays"). `parallax` is on the fine grid's frame (the maps' one: the same region);
// `fine_row0` is the first fine row of `fine_normals` (a band's).
Image SurfaceAreaWeights(const Image& fine_normals, const reconstruction::ViewParallax& parallax, int fine_row0 = 0);

// Each k x k block's mean weighted by `weights` (1 plane, the fine image's size); BlockMean when
// `weights` is empty. A block with no weight gets 0.
Image BlockWeightedMean(const Image& fine, const Image& weights, int k, double pitch_mm);

// The normalised sum of each k x k block's unit normals, each weighted by `weights` (empty: all
// 1; SurfaceAreaWeights); a block whose normals cancel keeps +z. Over a map pixel this is close to
// its area-average normal, the normal that integrates to its height (supersampled_reconstruction.h
// says why the maps' grid cannot give it). With `placement` on, each fine normal counts where its
// surface point lies in plan (plan_placement.h PlacedWeightedMean), not where its ray met the grid.
Image AverageNormalsOntoMaps(const Image& fine_normals, int k, double pitch_mm, const Image& weights = Image(),
                             const PlanPlacement& placement = PlanPlacement());

// A fine photometric stereo result on the maps' grid: normals AverageNormalsOntoMaps, albedo and
// (when set) height their block means, these three weighted by SurfaceAreaWeights(fine.normal,
// parallax, fine_row0) and, with `placement` on (the whole fine grid's: fine_row0 0), put where
// their surface points lie in plan (PlacedWeightedMean); confidence and used lights their block
// means; condition number the largest; the pixel counts in map pixels (rounded). The per-run
// figures (near-light rounds, diffuse roughness, last change) are copied.
reconstruction::PhotometricStereoResult AveragePhotometricStereoOntoMaps(
    const reconstruction::PhotometricStereoResult& fine, int k, double pitch_mm,
    const reconstruction::ViewParallax& parallax = {}, int fine_row0 = 0,
    const PlanPlacement& placement = PlanPlacement());

// The height of a side whose normals were refined on the fine grid (pitch_mm / k): its detail from
// `fine_height_mm` (integrated there; each map pixel the mean of its fine heights, the truth's own
// definition, which integrating on the maps' grid misses at the yarn steps) and its wavelengths
// longer than a few map pixels from `maps_height_mm` (integrated on the maps' grid, where the fine
// heights drift with a lean too small to see in their angles: plain at 2x, 9 um against 4 um).
// `weights` (empty: all 1) weigh the fine heights in their block means (SurfaceAreaWeights), and
// `placement` (when on) puts each where its surface point lies in plan (PlacedWeightedMean).
Image HeightFromFineAndMapsGrids(const Image& fine_height_mm, const Image& maps_height_mm, int k,
                                 const Image& weights = Image(), const PlanPlacement& placement = PlanPlacement());

}  // namespace u3mscan
