#pragma once
// The fitted base colour of a side, taken from the fit's per-pixel step on the finer grid
// (`--ps-supersample K`) and averaged onto the maps' grid.
//
// Why: a map pixel holds several yarn facets. Their radiance under a light is, for a diffuse
// surface, rho (mean of the facets' unit normals) . l = rho |n_mean| (n . l): one unit normal per
// pixel cannot hold the spread, so the maps' grid's fit puts |n_mean| < 1 into a darker colour.
// On the plain weave's truth at 3x, |n_mean| is 0.90 in the lowest height quintile (the crevices,
// where the walls are steep) and 0.99 on the yarn tops: L* 4.1 and 0.4 lower, as the maps' fit
// was (-4.4 and -0.2). A fine pixel holds a ninth of the facets and its fitted colour is close
// to the truth; their mean is the map pixel's colour (measured: docs/fitting.md, "Base colour
// from the finer grid"). The price: rendered with its one normal, the map pixel is brighter than
// its facets' mean in the crevices (the held-out re-render moves the other way).
//
// Accumulates in map pixels (16 B each), so the banded pipeline adds one fine band at a time
// without holding a fine colour map.

#include <cstddef>
#include <vector>

#include "core/image.h"
#include "pipeline/plan_placement.h"

namespace u3mscan {

class FineColourAverage {
 public:
  // The maps' grid (maps_width x maps_height pixels) and the fine grid's factor k >= 1.
  FineColourAverage(int maps_width, int maps_height, int k);

  // Adds fine rows [fine_row0, fine_row0 + base_color.height()) of the fine grid: `base_color` (3
  // channels, linear RGB) and `cluster_id` (1 channel) of the fit's per-pixel step on them, as wide
  // as the fine grid (maps_width k). Only fitted pixels count: cluster id >= 0 and a finite colour.
  // `weights` (1 channel, the rows' size; empty: all 1) weigh each fine pixel, e.g. its share of
  // the surface seen along the camera's rays (fine_grid.h SurfaceAreaWeights); a pixel of weight 0
  // does not count. With `placement` on (plan_placement.h, made for the whole fine grid), each
  // fine pixel counts where its surface point lies in plan, shared among the map pixels its moved
  // square overlaps. Throws std::invalid_argument when the rows do not lie on the fine grid.
  void Add(const Image& base_color, const Image& cluster_id, int fine_row0, const Image& weights = Image(),
           const PlanPlacement& placement = PlanPlacement());

  // Sets the base colour of every map pixel that the maps' fit fitted (`maps_cluster_id` >= 0) and
  // that has at least one fitted fine pixel to the (weighted) mean of its fitted fine pixels; the others keep
  // theirs. Returns the number of map pixels set. Throws std::invalid_argument when the maps are not
  // on the maps' grid.
  long long ApplyTo(const Image& maps_cluster_id, Image* maps_base_color) const;

 private:
  // One fine pixel's colour, weighted, shared among the map pixels its moved square overlaps.
  void AddPlaced(int fine_col, int fine_row, float weight, float red, float green, float blue,
                 const PlanPlacement& placement);

  int width_, height_, k_;
  std::vector<float> sum_;            // 3 per map pixel, linear RGB
  std::vector<float> weight_;         // summed weights of its fitted fine pixels (0: none), per map pixel
};

}  // namespace u3mscan
