#pragma once
// A camera's view of one map pixel as a mixture of facets: the pixel's normals on a grid `factor`
// times finer (photometric stereo there), each weighted by the area the camera sees of it.
//
// Why: a camera does not photograph a map pixel's area-average normal. Per unit of table area a
// facet of unit normal n has area 1 / n_z, of which the camera sees max(0, n.v) / n_z, so the
// pixel it photographs is the mean of its facets' reflections with those weights (from above: the
// plain mean of their reflections, which one normal does not give where the lobes are narrow or
// grazing). With one normal per pixel, the fit of a velvet's pile seen by a 60 deg camera read the
// dimmer far-side lights as less sheen (docs/fitting.md, "Where the velvet's sheen error comes
// from": sheen 0.666 for 0.955 with a 4x camera). The fit models each observation as the mixture
// of the facets below (fitting/brdf_cost.h, LocalObservation runs).
//
// Masking of one facet by another and the facets' cast shadows are left out: the weights are those
// of a surface with no occlusion below the fine grid's pitch.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>

#include "core/image.h"

namespace u3mscan::fitting {

// At most this many facets per pixel and view: the fine normals are grouped (weighted k-means,
// started from the 3 x 3 sub-blocks of the pixel) so that the fit's cost grows by a factor of at
// most this, not by factor^2 (25 at the 5x default; docs/fitting.md, "Facets of the finer grid").
inline constexpr int kMaxFacets = 9;
// Largest supported factor (fine pixels per map pixel along each axis).
inline constexpr int kMaxFacetFactor = 8;

struct Facet {
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  // unit, world frame
  double weight = 0.0;                                // share of the pixel's seen area; they sum to 1
};
using FacetSet = std::array<Facet, kMaxFacets>;

// The facets camera direction `view_world` (unit, world) sees in map pixel (col, row) of
// `fine_normals` (3 channels, unit world normals, `factor` times the maps' width and height):
// the pixel's factor x factor fine normals weighted by max(0, n.v) / max(n_z, 0.05), grouped into at
// most kMaxFacets (each group's normal the normalised weighted sum of its members, its weight their
// summed weight; groups within half a degree merged), the weights normalised to sum 1. Fine normals that are not finite or not of unit
// length (+- 0.5) are skipped. Returns the number of facets in `out` (0: none seen, use the pixel's
// own normal).
int ViewFacets(const Image& fine_normals, int factor, int col, int row, const Eigen::Vector3d& view_world,
               FacetSet* out);

// The turn that puts a world direction where the facet sees it relative to the pixel: seeing a
// facet tilted from the pixel's unit normal `pixel_normal` is seeing every direction turned back
// by that tilt. Shading the turned light and view in the pixel's frame shades the facet, whatever
// normal the pixel is later given (the fit's gather and RenderFitted both use it).
inline Eigen::Quaterniond TurnIntoFacet(const Eigen::Vector3d& pixel_normal, const Facet& facet) {
  return Eigen::Quaterniond::FromTwoVectors(pixel_normal, facet.normal).conjugate();
}

}  // namespace u3mscan::fitting
