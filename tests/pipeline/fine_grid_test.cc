// Averaging the finer grid onto the maps' grid along the camera's rays (pipeline/fine_grid.h
// SurfaceAreaWeights, BlockWeightedMean, AverageNormalsOntoMaps), and the height integrated from
// it (pipeline/supersampled_reconstruction.h IntegrateFineRefinedNormals).
#include "pipeline/fine_grid.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>

#include "pipeline/supersampled_reconstruction.h"
#include "tests/support/leaning_camera.h"

namespace u3mscan {
namespace {

constexpr float kExact = 1e-6f;  // float arithmetic on a few values of order 1
// The corrugation's weighted mean is a midpoint rule over one whole period of a smooth periodic
// integrand (16 samples): exact to far below this.
constexpr double kQuadratureDeg = 0.01;

double Degrees(double radians) { return radians * 180.0 / std::numbers::pi; }

using testing::CameraToTheLeft;

// A corrugation z = A sin(2 pi x / P) whose period P is one map pixel (steepest slope 0.5),
// `maps` x `rows` map pixels of `fine` fine pixels a side, as the camera sees it through
// `parallax`'s rays: each fine pixel holds the unit normal of the surface point its ray reaches,
// x_h = x_g + z(x_h) t (the fixed point of a contraction: |z' t| <= 0.1).
Image CorrugationSeenAlongTheRays(const reconstruction::ViewParallax& parallax, int maps, int rows, int fine,
                                  double period) {
  const double fine_pitch = period / fine;
  const double amplitude = 0.5 * period / (2.0 * std::numbers::pi);
  Image normals(maps * fine, rows * fine, 3, 0.0f, fine_pitch);
  for (int c = 0; c < normals.width(); ++c) {
    const double x_grid = (c + 0.5) * fine_pitch;
    const double t = (parallax.camera_x_mm - x_grid) / parallax.camera_z_mm;
    double x_seen = x_grid;
    for (int i = 0; i < 60; ++i) x_seen = x_grid + amplitude * std::sin(2.0 * std::numbers::pi * x_seen / period) * t;
    const double slope = amplitude * 2.0 * std::numbers::pi / period * std::cos(2.0 * std::numbers::pi * x_seen / period);
    const double length = std::sqrt(1.0 + slope * slope);
    for (int r = 0; r < normals.height(); ++r) {
      normals.at(0, r, c) = static_cast<float>(-slope / length);
      normals.at(2, r, c) = static_cast<float>(1.0 / length);
    }
  }
  return normals;
}

TEST(SurfaceAreaWeights, AFacetFacingTheCameraWeighsLessThanOneTurnedAway) {
  const reconstruction::ViewParallax parallax = CameraToTheLeft();
  const double pitch = 0.01;
  Image normals(2, 1, 3, 0.0f, pitch);
  // Slope s = -n_x / n_z = +0.5 (the facet faces -x, the camera) and -0.5 (faces away).
  const double nz = 1.0 / std::sqrt(1.25), nx = 0.5 * nz;
  normals.at(0, 0, 0) = static_cast<float>(-nx), normals.at(2, 0, 0) = static_cast<float>(nz);
  normals.at(0, 0, 1) = static_cast<float>(nx), normals.at(2, 0, 1) = static_cast<float>(nz);
  const Image weights = SurfaceAreaWeights(normals, parallax);
  for (int c = 0; c < 2; ++c) {
    const double x = (c + 0.5) * pitch, y = -0.5 * pitch;
    const double tx = (-60.0 - x) / 300.0, ty = (0.0 - y) / 300.0;
    const double slope_x = c == 0 ? 0.5 : -0.5;
    EXPECT_NEAR(weights.at(0, 0, c), 1.0 / (1.0 - (slope_x * tx + 0.0 * ty)), kExact) << c;
  }
  EXPECT_LT(weights.at(0, 0, 0), 1.0f);
  EXPECT_GT(weights.at(0, 0, 1), 1.0f);

  // Off: no weights (every one 1), and so the plain block mean.
  EXPECT_TRUE(SurfaceAreaWeights(normals, reconstruction::ViewParallax{}).empty());
}

TEST(SurfaceAreaWeights, ABandsRowsGetTheWholeGridsWeights) {
  reconstruction::ViewParallax parallax = CameraToTheLeft();
  parallax.camera_y_mm = 40.0;  // the rays lean in y too, so the row matters
  Image whole(3, 6, 3, 0.0f, 0.05);
  for (int r = 0; r < 6; ++r) {
    for (int c = 0; c < 3; ++c) {
      whole.at(0, r, c) = 0.1f * static_cast<float>(c - 1);
      whole.at(1, r, c) = 0.3f;
      whole.at(2, r, c) = 0.9f;
    }
  }
  Image band(3, 2, 3, 0.0f, 0.05);  // rows 4 and 5
  for (int ch = 0; ch < 3; ++ch) {
    for (int r = 0; r < 2; ++r) {
      for (int c = 0; c < 3; ++c) band.at(ch, r, c) = whole.at(ch, 4 + r, c);
    }
  }
  const Image a = SurfaceAreaWeights(whole, parallax), b = SurfaceAreaWeights(band, parallax, 4);
  for (int r = 0; r < 2; ++r) {
    for (int c = 0; c < 3; ++c) EXPECT_FLOAT_EQ(a.at(0, 4 + r, c), b.at(0, r, c)) << r << "," << c;
  }
  EXPECT_NE(a.at(0, 0, 1), a.at(0, 5, 1));  // the test would not see a wrong row otherwise
}

TEST(BlockWeightedMean, EachBlocksWeightedMean) {
  Image fine(4, 2, 1, 0.0f, 0.5);
  Image weights(4, 2, 1, 1.0f, 0.5);
  for (int c = 0; c < 4; ++c) fine.at(0, 0, c) = fine.at(0, 1, c) = static_cast<float>(c);
  weights.at(0, 0, 0) = weights.at(0, 1, 0) = 3.0f;  // block 0: (3 * 0 + 1 * 1) / 4
  weights.at(0, 0, 3) = weights.at(0, 1, 3) = 0.0f;  // block 1: column 2 alone
  const Image out = BlockWeightedMean(fine, weights, 2, 1.0);
  ASSERT_EQ(out.width(), 2);
  ASSERT_EQ(out.height(), 1);
  EXPECT_DOUBLE_EQ(out.pitch_mm(), 1.0);
  EXPECT_NEAR(out.at(0, 0, 0), 0.25f, kExact);
  EXPECT_NEAR(out.at(0, 0, 1), 2.0f, kExact);
  const Image plain = BlockWeightedMean(fine, Image(), 2, 1.0);  // no weights: the block means
  EXPECT_NEAR(plain.at(0, 0, 0), 0.5f, kExact);
  EXPECT_NEAR(plain.at(0, 0, 1), 2.5f, kExact);
  EXPECT_THROW(BlockWeightedMean(fine, Image(4, 1, 1, 1.0f), 2, 1.0), std::invalid_argument);
}

TEST(AverageNormalsOntoMaps, WeightedBySurfaceAreaTheCorrugationsNormalDoesNotLeanTowardTheCamera) {
  // A corrugation z = A sin(2 pi x / P) whose period P is one map pixel, seen at 16 fine pixels a
  // map pixel through CameraToTheLeft's rays (t about -0.2 in x). The truth's normal of a map pixel
  // is the mean over its plan of the unit normals: over a whole period that is +z. A fine pixel
  // shows the surface point its ray reaches, x_h = x_g + z(x_h) t, so the facets facing the camera
  // fill more fine pixels than their plan: the plain mean leans toward the camera.
  const reconstruction::ViewParallax parallax = CameraToTheLeft();
  constexpr int kMaps = 8, kFine = 16;
  const double period = 0.1;
  const Image normals = CorrugationSeenAlongTheRays(parallax, kMaps, 1, kFine, period);  // one row of map pixels
  const Image plain = AverageNormalsOntoMaps(normals, kFine, period);
  const Image weighted = AverageNormalsOntoMaps(normals, kFine, period, SurfaceAreaWeights(normals, parallax));
  for (int c = 0; c < kMaps; ++c) {
    // Plain: about E[s^2] |t| = 0.125 * 0.2 = 0.025 in slope (1.4 deg), toward the camera (-x).
    EXPECT_GT(Degrees(std::acos(plain.at(2, 0, c))), 1.0) << c;
    EXPECT_LT(plain.at(0, 0, c), 0.0f) << c;
    EXPECT_LT(Degrees(std::acos(std::min(1.0f, weighted.at(2, 0, c)))), kQuadratureDeg) << c;
    EXPECT_NEAR(std::hypot(weighted.at(0, 0, c), weighted.at(1, 0, c), weighted.at(2, 0, c)), 1.0, kExact);
  }
}

TEST(IntegrateFineRefinedNormals, ACorrugationSeenAlongLeaningRaysKeepsItsMapFlat) {
  // The corrugation above over 16 x 4 map pixels. Every map pixel holds one whole period, so their
  // mean heights are equal: the map is flat. The long wavelengths come from the fine normals'
  // average along the rays (docs/reconstruction.md, "Where the bowl came from"). Averaged without
  // the surface weights (empty weights passed here) the map ramps by 23 um peak to valley.
  const reconstruction::ViewParallax parallax = CameraToTheLeft();
  constexpr int kMaps = 16, kMapRows = 4, kFine = 16;
  constexpr double kPeriodMm = 0.1;
  // 2 % of the corrugation's 16 um peak to valley.
  constexpr double kFlatToleranceMm = 0.3e-3;
  Image fine_normals = CorrugationSeenAlongTheRays(parallax, kMaps, kMapRows, kFine, kPeriodMm);
  const Image weights = SurfaceAreaWeights(fine_normals, parallax);
  ASSERT_FALSE(weights.empty());
  StageOptions options;
  options.integration.parallax = parallax;
  const Image fine_valid(fine_normals.width(), fine_normals.height(), 1, 1.0f, fine_normals.pitch_mm());
  const Image maps_valid(kMaps, kMapRows, 1, 1.0f, kPeriodMm);
  const Image expected_average = AverageNormalsOntoMaps(fine_normals, kFine, kPeriodMm, weights);
  Image average;
  const Image height = IntegrateFineRefinedNormals(std::move(fine_normals), fine_valid, weights, maps_valid, kFine,
                                                   kPeriodMm, /*near=*/false, options, {}, PlanPlacement(), &average);
  // The average it integrated is handed back: the normal map the caller writes.
  ASSERT_EQ(average.width(), kMaps);
  ASSERT_EQ(average.height(), kMapRows);
  for (int ch = 0; ch < 3; ++ch) {
    for (int r = 0; r < kMapRows; ++r) {
      for (int c = 0; c < kMaps; ++c) EXPECT_EQ(average.at(ch, r, c), expected_average.at(ch, r, c)) << ch << r << c;
    }
  }
  ASSERT_EQ(height.width(), kMaps);
  ASSERT_EQ(height.height(), kMapRows);
  EXPECT_DOUBLE_EQ(height.pitch_mm(), kPeriodMm);
  float low = height.at(0, 0, 0), high = low;
  for (int r = 0; r < kMapRows; ++r) {
    for (int c = 0; c < kMaps; ++c) {
      ASSERT_TRUE(std::isfinite(height.at(0, r, c))) << r << ", " << c;
      low = std::min(low, height.at(0, r, c));
      high = std::max(high, height.at(0, r, c));
    }
  }
  EXPECT_LT(high - low, kFlatToleranceMm);
}

}  // namespace
}  // namespace u3mscan
