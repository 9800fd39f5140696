#include "fitting/facet_mixture.h"

#include <algorithm>
#include <cmath>

namespace u3mscan::fitting {
namespace {

// A fine normal is used when its length is within this of 1 (photometric stereo writes unit
// normals, and 0 where it has none).
constexpr double kUnitLengthSlack = 0.5;
// n_z below this is taken as this: a facet seen edge-on from above would otherwise weigh without
// bound (its table area is tiny, its tilt counts once).
constexpr double kMinFacetNz = 0.05;
// Groups along each axis of the pixel's block that start the k-means (3 x 3 = kMaxFacets).
constexpr int kGroupsPerAxis = 3;
static_assert(kGroupsPerAxis * kGroupsPerAxis == kMaxFacets);
// Reassignment passes of the k-means: the sub-block start is already close on smooth relief.
constexpr int kGroupingPasses = 3;
// Groups closer than this (deg) are merged: the mixture of two facets that close differs from
// their mean by a second-order term of the angle (1e-4 rad^2 at 0.5 deg).
constexpr double kMergeAngleDeg = 0.5;
// A group whose weighted normals cancel has no direction.
constexpr double kTinyLength = 1e-12;

}  // namespace

int ViewFacets(const Image& fine_normals, int factor, int col, int row, const Eigen::Vector3d& view_world,
               FacetSet* out) {
  constexpr int kMaxFine = kMaxFacetFactor * kMaxFacetFactor;
  Eigen::Vector3d normal[kMaxFine];
  double weight[kMaxFine];
  int group[kMaxFine];
  int count = 0;
  const int k = std::clamp(factor, 1, kMaxFacetFactor);
  for (int j = 0; j < k; ++j) {
    for (int i = 0; i < k; ++i) {
      const int fine_row = row * k + j, fine_col = col * k + i;
      Eigen::Vector3d n(fine_normals.at(0, fine_row, fine_col), fine_normals.at(1, fine_row, fine_col),
                        fine_normals.at(2, fine_row, fine_col));
      const double length = n.norm();
      if (!n.allFinite() || std::abs(length - 1.0) > kUnitLengthSlack) continue;
      n /= length;
      const double w = std::max(0.0, n.dot(view_world)) / std::max(kMinFacetNz, n.z());
      if (!(w > 0.0)) continue;
      normal[count] = n;
      weight[count] = w;
      group[count] = (kGroupsPerAxis * j / k) * kGroupsPerAxis + kGroupsPerAxis * i / k;
      ++count;
    }
  }
  // Weighted k-means on the unit sphere (cosine similarity), started from the sub-blocks.
  FacetSet& facets = *out;
  auto centre = [&] {
    for (Facet& f : facets) {
      f.normal.setZero();
      f.weight = 0.0;
    }
    for (int m = 0; m < count; ++m) {
      facets[group[m]].normal += weight[m] * normal[m];
      facets[group[m]].weight += weight[m];
    }
    for (Facet& f : facets) {
      const double length = f.normal.norm();
      if (length > kTinyLength) {
        f.normal /= length;
      } else {
        f.weight = 0.0;  // members facing opposite ways: no direction to give
      }
    }
  };
  centre();
  for (int pass = 0; pass < kGroupingPasses; ++pass) {
    for (int m = 0; m < count; ++m) {
      double best = -2.0;
      for (int g = 0; g < kMaxFacets; ++g) {
        if (facets[g].weight > 0.0 && normal[m].dot(facets[g].normal) > best) {
          best = normal[m].dot(facets[g].normal);
          group[m] = g;
        }
      }
    }
    centre();
  }
  // Groups whose normals agree within kMergeAngleDeg are one facet: a smooth pixel costs the fit one
  // entry, not nine.
  static const double cos_merge = std::cos(kMergeAngleDeg * M_PI / 180.0);
  double total = 0.0;
  int kept = 0;
  for (int g = 0; g < kMaxFacets; ++g) {
    if (!(facets[g].weight > 0.0)) continue;
    total += facets[g].weight;
    int same = 0;
    while (same < kept && facets[same].normal.dot(facets[g].normal) < cos_merge) ++same;
    if (same < kept) {
      const double w = facets[same].weight + facets[g].weight;
      facets[same].normal = (facets[same].weight * facets[same].normal + facets[g].weight * facets[g].normal).normalized();
      facets[same].weight = w;
    } else {
      facets[kept++] = facets[g];
    }
  }
  for (int g = 0; g < kept; ++g) facets[g].weight /= total;
  return kept;
}

}  // namespace u3mscan::fitting
