#pragma once
// Where each pixel of the finer grid (`--ps-supersample K`) lies on the sample's plan, and the
// averages onto the maps' grid that put it there.
//
// Why: the grid is rectified onto the plane of the sample's face, so a grid point x_g holds the
// surface point its camera ray reaches, x_s = x_g + (z - plane) t (t: the ray's horizontal lean,
// reconstruction/normal_integration.h ViewParallax). Below the face z - plane < 0: the point lies
// further from the camera, by its depth, so a valley moves and a yarn top does not. On a 36 MP
// scan (117 mm map at 300 dpi, camera 300 mm above) that is up to 43 um, half a map pixel, at the
// edges. The truth's maps, and a renderer's, are on the plan: the normals were 2.74 deg from the
// plan truth there and 0.67 deg from the truth sampled where the rays reach (docs/reconstruction.md,
// "Large maps: the maps lie where the camera's rays reach"). The shift changes within a map pixel,
// so it is made on the fine grid: each fine pixel's square is moved to its surface point's plan
// position and shared among the map pixels it then overlaps.

#include <string>

#include "core/image.h"
#include "reconstruction/normal_integration.h"

namespace u3mscan {

// A fine pixel whose offset would be larger than this many map pixels has a height that the
// integration got wrong (a spike): its offset is kept at it.
inline constexpr double kMaxPlanOffsetMapPx = 2.0;

// The fine heights' wavelengths longer than this Gaussian sigma (map pixels) are left out of the
// depths (PlanPlacement), after a quadratic over the map. The quadratic takes the integration's
// bowl: on the 9 MP plain's truth seen along the rays (throwaway numpy), with a 100 um bowl added
// to the heights, the normals read 1.98 deg from the plan with the bowl kept and 0.58 without it.
// A short sigma takes a fabric's own wide hollows too (a velvet's crushed pile): the 2048 px velvet
// of the oblique rig at 4x read 0.814 deg with 16 alone, 0.728 with the quadratic and 64
// (docs/reconstruction.md, "Placing the fine pixels on the plan").
inline constexpr double kPlacementReliefSigmaMapPx = 64.0;

class PlanPlacement {
 public:
  // Off: every offset 0 (the averages below are then the plain block averages).
  PlanPlacement() = default;

  // `fine_height_mm`: the heights of the whole fine grid (k times the maps' grid; integrated, known
  // up to a constant). A quadratic over the map and then their wavelengths longer than
  // kPlacementReliefSigmaMapPx are taken out (the sample lies on the face's plane; `fine_valid`, 1
  // channel of the same size or empty, weighs the quadratic's fit), and the top of the rest
  // (relief_registration.h ReliefTopMm over `fine_valid`) is put on the parallax's plane, the
  // sample's face (the manifest's thickness is the sample's highest point).
  // `parallax` is the maps' one (the same region and plane). Off when the parallax is off or
  // there is no height.
  PlanPlacement(const Image& fine_height_mm, const Image& fine_valid, const reconstruction::ViewParallax& parallax,
                int k);

  bool enabled() const { return !below_face_mm_.empty(); }
  int k() const { return k_; }
  int width() const { return below_face_mm_.width(); }    // fine pixels (0 when off)
  int height() const { return below_face_mm_.height(); }

  // The offset of fine pixel (col, row)'s surface point from its grid position, in fine pixels:
  // `d_col` along the columns (+x), `d_row` along the rows (-y). 0 when off.
  void OffsetFinePx(int col, int row, float* d_col, float* d_row) const;

  // The largest |offset| of any fine pixel, rounded up (fine pixels).
  int margin_fine_px() const { return margin_fine_px_; }

  // The largest |offset| (fine pixels), for the report.
  double largest_offset_fine_px() const { return largest_offset_fine_px_; }

 private:
  Image below_face_mm_;  // z - plane per fine pixel (<= 0 below the top; 0 where unknown)
  reconstruction::ViewParallax parallax_;
  double fine_pitch_mm_ = 0.0;
  int k_ = 1;
  int margin_fine_px_ = 0;
  double largest_offset_fine_px_ = 0.0;
};

// For the report: "; fine pixels placed on the plan (up to N um)" when `placement` is on (N: its
// largest offset at fine pitch `fine_pitch_mm`), else empty.
std::string PlacementDetail(const PlanPlacement& placement, double fine_pitch_mm);

// The share (0..1) of a fine pixel's unit square, its left (top) edge at `fine_edge` fine pixels,
// that lies within map pixel `map` (k fine pixels a side), along one axis.
inline double PlacedOverlap(double fine_edge, int map, int k) {
  const double low = static_cast<double>(map) * k, high = low + k;
  const double overlap = (fine_edge + 1.0 < high ? fine_edge + 1.0 : high) - (fine_edge > low ? fine_edge : low);
  return overlap > 0.0 ? overlap : 0.0;
}

// Each map pixel (k fine pixels a side, pitch `pitch_mm`) the mean of the fine pixels whose squares, moved to their
// surface points' plan positions, overlap it, each weighted by `weights` (1 plane, the fine
// image's size; empty: all 1) times the share of its square inside. A map pixel that no fine
// pixel reaches (a border the moved squares left) keeps its own block's weighted mean.
// BlockWeightedMean (fine_grid.h) when `placement` is off. Throws std::invalid_argument when
// `placement` is on and was made for another factor or grid.
Image PlacedWeightedMean(const Image& fine, const Image& weights, const PlanPlacement& placement, int k,
                         double pitch_mm);

}  // namespace u3mscan
