#include "fitting/facet_mixture.h"

#include <gtest/gtest.h>

#include <cmath>
#include <functional>

namespace u3mscan::fitting {
namespace {

// Sums and normals are formed in double from float images: exact to float rounding.
constexpr double kTolerance = 1e-6;

Eigen::Vector3d Tilted(double tilt_deg, double azimuth_deg) {
  const double t = tilt_deg * M_PI / 180.0, a = azimuth_deg * M_PI / 180.0;
  return {std::sin(t) * std::cos(a), std::sin(t) * std::sin(a), std::cos(t)};
}

// One map pixel's k x k fine normals, normal(i, j) at fine column i and row j.
Image Block(int k, const std::function<Eigen::Vector3d(int, int)>& normal) {
  Image fine(k, k, 3, 0.0f, 0.1);
  for (int j = 0; j < k; ++j) {
    for (int i = 0; i < k; ++i) {
      const Eigen::Vector3d n = normal(i, j);
      for (int c = 0; c < 3; ++c) fine.at(c, j, i) = static_cast<float>(n(c));
    }
  }
  return fine;
}

double WeightSum(const FacetSet& facets, int count) {
  double sum = 0.0;
  for (int f = 0; f < count; ++f) sum += facets[f].weight;
  return sum;
}

TEST(FacetMixture, AFlatPixelIsOneFacet) {
  const Eigen::Vector3d n = Tilted(12.0, 30.0);
  const Image fine = Block(5, [&](int, int) { return n; });
  FacetSet facets;
  ASSERT_EQ(ViewFacets(fine, 5, 0, 0, Tilted(60.0, 0.0), &facets), 1);
  EXPECT_NEAR(facets[0].weight, 1.0, kTolerance);
  EXPECT_NEAR(facets[0].normal.dot(n), 1.0, kTolerance);
}

TEST(FacetMixture, TheTiltedCameraWeighsEachFacetByTheAreaItSees) {
  // Two ridges' flanks: left half of the pixel tilted 30 deg toward +x, right half 20 deg toward -x.
  // A camera 60 deg toward +x sees the left flank face-on (30 deg off) and the right one nearly
  // edge-on (80 deg off).
  const Eigen::Vector3d toward = Tilted(30.0, 0.0), away = Tilted(20.0, 180.0);
  const Image fine = Block(4, [&](int i, int) { return i < 2 ? toward : away; });
  const Eigen::Vector3d view = Tilted(60.0, 0.0);
  FacetSet facets;
  ASSERT_EQ(ViewFacets(fine, 4, 0, 0, view, &facets), 2);
  EXPECT_NEAR(WeightSum(facets, 2), 1.0, kTolerance);
  const double w_toward = toward.dot(view) / toward.z(), w_away = away.dot(view) / away.z();
  const Facet& first = facets[0].normal.dot(toward) > facets[1].normal.dot(toward) ? facets[0] : facets[1];
  const Facet& second = &first == &facets[0] ? facets[1] : facets[0];
  EXPECT_NEAR(first.normal.dot(toward), 1.0, kTolerance);
  EXPECT_NEAR(second.normal.dot(away), 1.0, kTolerance);
  EXPECT_NEAR(first.weight, w_toward / (w_toward + w_away), kTolerance);
  EXPECT_NEAR(second.weight, w_away / (w_toward + w_away), kTolerance);
  EXPECT_GT(first.weight, 5.0 * second.weight);

  // From straight above each facet weighs its table area alone: the two halves equally.
  ASSERT_EQ(ViewFacets(fine, 4, 0, 0, Eigen::Vector3d::UnitZ(), &facets), 2);
  EXPECT_NEAR(facets[0].weight, 0.5, kTolerance);
  EXPECT_NEAR(facets[1].weight, 0.5, kTolerance);
}

TEST(FacetMixture, FacetsTurnedAwayFromTheCameraAndMissingNormalsAreNotSeen) {
  // Column 0 faces away from a camera at 70 deg (tilted 40 deg the other way: n.v < 0), column 1 has
  // no normal (0, as photometric stereo writes where it has none), the rest is flat.
  const Image fine = Block(3, [&](int i, int) {
    if (i == 0) return Tilted(40.0, 180.0);
    if (i == 1) return Eigen::Vector3d(0.0, 0.0, 0.0);
    return Eigen::Vector3d(0.0, 0.0, 1.0);
  });
  FacetSet facets;
  ASSERT_EQ(ViewFacets(fine, 3, 0, 0, Tilted(70.0, 0.0), &facets), 1);
  EXPECT_NEAR(facets[0].normal.z(), 1.0, kTolerance);
  EXPECT_NEAR(facets[0].weight, 1.0, kTolerance);

  const Image dark = Block(3, [](int, int) { return Eigen::Vector3d(0.0, 0.0, 0.0); });
  EXPECT_EQ(ViewFacets(dark, 3, 0, 0, Tilted(60.0, 0.0), &facets), 0);
}

TEST(FacetMixture, ASpreadOfNormalsIsGroupedIntoAtMostTheCapWithTheirMeanKept) {
  // 5 x 5 facets on a bump: every fine normal different. The groups keep the seen-area weighted
  // mean normal: the sum of weight x normal before normalising is the same as the fine normals'.
  const Image fine = Block(5, [](int i, int j) { return Tilted(6.0 * (i + j), 40.0 * i - 25.0 * j); });
  const Eigen::Vector3d view = Tilted(55.0, 20.0);
  FacetSet facets;
  const int count = ViewFacets(fine, 5, 0, 0, view, &facets);
  ASSERT_GT(count, 1);
  ASSERT_LE(count, kMaxFacets);
  EXPECT_NEAR(WeightSum(facets, count), 1.0, kTolerance);
  Eigen::Vector3d fine_mean = Eigen::Vector3d::Zero(), grouped_mean = Eigen::Vector3d::Zero();
  for (int j = 0; j < 5; ++j) {
    for (int i = 0; i < 5; ++i) {
      const Eigen::Vector3d n(fine.at(0, j, i), fine.at(1, j, i), fine.at(2, j, i));
      fine_mean += std::max(0.0, n.dot(view)) / n.z() * n.normalized();
    }
  }
  for (int f = 0; f < count; ++f) grouped_mean += facets[f].weight * facets[f].normal;
  // Normalising each group shortens its sum a little (its members spread): directions agree
  // within a degree.
  EXPECT_GT(fine_mean.normalized().dot(grouped_mean.normalized()), std::cos(1.0 * M_PI / 180.0));
}

TEST(FacetMixture, EachMapPixelReadsItsOwnBlock) {
  // Two map pixels side by side at factor 2: the left one flat, the right one tilted.
  Image fine(4, 2, 3, 0.0f, 0.1);
  const Eigen::Vector3d tilted = Tilted(25.0, 90.0);
  for (int j = 0; j < 2; ++j) {
    for (int i = 0; i < 4; ++i) {
      const Eigen::Vector3d n = i < 2 ? Eigen::Vector3d::UnitZ() : tilted;
      for (int c = 0; c < 3; ++c) fine.at(c, j, i) = static_cast<float>(n(c));
    }
  }
  FacetSet facets;
  ASSERT_EQ(ViewFacets(fine, 2, 1, 0, Tilted(45.0, 90.0), &facets), 1);
  EXPECT_NEAR(facets[0].normal.dot(tilted), 1.0, kTolerance);
}

}  // namespace
}  // namespace u3mscan::fitting
