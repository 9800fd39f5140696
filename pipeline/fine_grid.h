#pragma once
// The finer grid that photometric stereo runs on with `--ps-supersample K`
// (supersampled_reconstruction.h for one band, tiled_side.h for bands): the grid itself, its
// calibration, and the resampling between it and the maps' grid. Fine pixel (k col + i, k row + j)
// is the (i, j) part of map pixel (col, row).

#include "capture/calibrate.h"
#include "core/image.h"
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

// Back onto the maps' grid (pitch `pitch_mm`): each k x k block's mean, and its largest value.
Image BlockMean(const Image& fine, int k, double pitch_mm);
Image BlockMax(const Image& fine, int k, double pitch_mm);

// The normalised sum of each k x k block's unit normals; a block whose normals cancel keeps +z.
// Over a map pixel this is close to its area-average normal, the normal that integrates to its
// height (supersampled_reconstruction.h says why the maps' grid cannot give it).
Image AverageNormalsOntoMaps(const Image& fine_normals, int k, double pitch_mm);

// A fine photometric stereo result on the maps' grid: normals AverageNormalsOntoMaps; albedo,
// confidence, used lights and (when set) height their block means; condition number the largest;
// the pixel counts in map pixels (rounded). The per-run figures (near-light rounds, diffuse
// roughness, last change) are copied.
reconstruction::PhotometricStereoResult AveragePhotometricStereoOntoMaps(const reconstruction::PhotometricStereoResult& fine,
                                                                         int k, double pitch_mm);

// The height of a side whose normals were refined on the fine grid (pitch_mm / k): its detail from
// `fine_height_mm` (integrated there; each map pixel the mean of its fine heights, the truth's own
// definition, which integrating on the maps' grid misses at the yarn steps) and its wavelengths
// longer than a few map pixels from `maps_height_mm` (integrated on the maps' grid, where the fine
// heights drift with a lean too small to see in their angles: plain at 2x, 9 um against 4 um).
Image HeightFromFineAndMapsGrids(const Image& fine_height_mm, const Image& maps_height_mm, int k);

}  // namespace u3mscan
