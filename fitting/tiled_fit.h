#pragma once
// The fit in two parts, for scans whose whole Stack does not fit in memory (docs/process.md,
// "Large scans: memory and time"):
//   1. FitClusterModel on a sample Stack (e.g. every k-th row and column of the grid, which is again
//      a MetricGrid of pitch k p): gather, clustering, cluster fits, observability (FitPrincipled's
//      stages 1-4);
//   2. FitPixelRows band by band with the clusters fixed (stage 5, per pixel), into full-size maps,
//      then FinishPixelMaps (pixel counts, map decisions: left out, constant or texture).
// FitPrincipled is exactly StartPixelMaps + FitPixelRows over the whole grid + FinishPixelMaps on a
// model fitted on the same Stack, so a one-band run gives FitPrincipled's result.

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "core/progress.h"
#include "core/stack.h"
#include "fitting/principled_fit.h"

namespace u3mscan::fitting {

// What the per-pixel step needs from the cluster fits.
struct ClusterModel {
  FitOptions options;
  Clustering clustering;                  // centroids for NearestCluster
  // Noise level (median luminance) of each observation of the fitted Stack; bands must list the
  // same observations in the same order (the same frames), and take these levels.
  std::vector<double> observation_levels;
  std::vector<ClusterFit> clusters;
  ConvergenceReport convergence;          // cluster problems (pixel counts come later)
  StageTimes times;                       // gather, clustering, cluster fit
  std::array<bool, kFitParameterCount> measured_any{};  // maps that exist
  // Per parameter, why its clusters hold one value (HoldUniformClusterMaps); "" where they do not.
  std::array<std::string, kFitParameterCount> uniform_reason;
};

// Running sums of the per-pixel step over the bands (FinishPixelMaps turns them into the report).
struct PixelTally {
  std::vector<std::int64_t> cluster_pixels;
  std::int64_t fitted = 0, refined = 0;
  std::array<double, kFitParameterCount> variance_delta{};  // sum of (pixel - cluster) variance of refined pixels
  double seconds = 0.0;
};

// Stages 1-4 on `stack`. Throws like FitPrincipled.
ClusterModel FitClusterModel(const Stack& stack, const SurfaceGeometry& geometry, const FitOptions& options,
                             const ProgressCallback& progress = {});

// A FitResult with the model's clusters and full-size maps on `grid` at their defaults (base colour
// 0, cluster_id -1; a map whose parameter no cluster measured stays empty).
FitResult StartPixelMaps(const ClusterModel& model, const MetricGrid& grid);

// The per-pixel step on a band: `band` covers rows [row0, row0 + band.grid.height) of the result's
// grid (same width), `geometry` is on the band's grid. Throws std::invalid_argument when the band
// does not fit the result or its observations are not the model's.
void FitPixelRows(const ClusterModel& model, const Stack& band, const SurfaceGeometry& geometry, int row0,
                  FitResult* result, PixelTally* tally, const ProgressCallback& progress = {});

// Pixel counts, convergence figures and the map decisions, once every band is done.
void FinishPixelMaps(const ClusterModel& model, const PixelTally& tally, FitResult* result);

// FitPrincipled, handing back in `model` (not null) the cluster model its maps were made from, for a
// later per-pixel step on other observations (pipeline/top_view_normals.h).
FitResult FitPrincipled(const Stack& stack, const SurfaceGeometry& geometry, const FitOptions& options,
                        const ProgressCallback& progress, ClusterModel* model);

}  // namespace u3mscan::fitting
