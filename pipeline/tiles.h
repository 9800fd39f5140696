#pragma once
// Tiles of a side for scans whose whole Stack does not fit the memory budget (docs/process.md,
// "Large scans: memory and time"): the grid is cut into bands of whole rows, each band's Stack is
// built (capture/stack_builder.h), used and dropped.
//
// Memory model, bytes per grid pixel of a band (docs/process.md gives the calculation):
//   observations   n_obs * (12 rgb + 1 flags [+ 4 irradiance with flat fields])
//   working        kWorkingBytesPerPixel: photometric stereo's per-pixel results and scratch of a
//                  band (~54 B), one frame's rectification (~26 B on the grid plus its camera rows)

#include <cstddef>
#include <cstdint>

#include "core/image.h"
#include "core/stack.h"

namespace u3mscan {

inline constexpr double kWorkingBytesPerPixel = 128.0;
// The band Stacks' default budget: fixed, not taken from the machine, so that the same capture is
// cut the same way (and gives the same material) everywhere. 4 GiB keeps a 36 MP, 32-light scan in
// three bands with everything else (~3 GiB of full-size maps) well inside 24 GiB.
inline constexpr double kDefaultStackBudgetGiB = 4.0;
inline constexpr double kBytesPerGiB = 1024.0 * 1024.0 * 1024.0;
// The fit's sample (every k-th row and column) gets this share of the budget...
inline constexpr double kSampleShareOfBudget = 0.25;
// ...but keeps at least this many pixels (k is lowered, down to 1, until it does): k-means takes up
// to 20000 candidates (ClusteringOptions::max_samples), which a smaller sample would not have.
inline constexpr double kMinSamplePixels = 20000.0;

struct TilePlan {
  int bands = 1;            // 1: the whole stack at once (the untiled path)
  int band_rows = 0;        // grid rows per band (the last band may have fewer)
  int sample_step = 1;      // k: the fit's clusters are fitted on every k-th row and column
  double bytes_per_pixel = 0.0;     // of a band, per grid pixel (memory model above; per fine pixel with a fine factor)
  double whole_stack_bytes = 0.0;   // the same for the whole grid (the fine grid with a fine factor)
  int fine_factor = 1;              // the bands' stacks are on a grid this many times finer (--ps-supersample)
};

// observations: of the side's stack; flats: whether observations carry a measured irradiance.
// sample_step is the largest k whose sample fits kSampleShareOfBudget of the budget, lowered until
// the sample has kMinSamplePixels (1 on small grids: the sample is the whole grid).
// fine_factor k > 1 (photometric stereo on RefineGrid(grid, k), pipeline/fine_grid.h): each band's
// stack is also built k times finer, k^2 the bytes of its rows, and it is that stack that must fit
// the budget; band_rows stay rows of `grid` (k band_rows rows of the fine grid). The sample stays
// on `grid`, its step from the maps' stack as without the factor, but it is kept beside a band:
// with more than one band it takes kSampleShareOfBudget of the budget even when the maps' whole
// stack would fit.
TilePlan PlanTiles(const MetricGrid& grid, int observations, bool flats, double budget_bytes, int fine_factor = 1);

// The sample grid of step k: pixel (i, j) is grid pixel (k j + k/2, k i + k/2), so its centre lies
// where that pixel's does (pitch k p).
MetricGrid SampleGrid(const MetricGrid& grid, int step);
// Copies the sampled pixels of an image covering grid rows [row0, row0 + image rows) into `sample`
// (allocated on the sample grid when empty).
void SampleRows(const Image& band, int row0, int step, const MetricGrid& sample_grid, Image* sample);
// The fine pixels of the sampled pixels: `fine` covers the whole grid `fine_factor` k times finer
// (k rows and columns a grid pixel); sample pixel (i, j) gets the k x k block of its grid pixel, so
// the result is the sample grid k times finer (fitting::SurfaceGeometry::fine_normals of a sample).
Image SampleFineBlocks(const Image& fine, int fine_factor, int step, const MetricGrid& sample_grid);

}  // namespace u3mscan
