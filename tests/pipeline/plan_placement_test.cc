// Placing the finer grid's pixels where their surface points lie in plan before averaging them
// onto the maps (pipeline/plan_placement.h), and the base colour's average that does the same
// (pipeline/fine_colour.h).
#include "pipeline/plan_placement.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <numbers>
#include <utility>

#include "pipeline/fine_colour.h"
#include "pipeline/fine_grid.h"
#include "tests/support/leaning_camera.h"

namespace u3mscan {
namespace {

constexpr double kFloatExact = 1e-5;  // float sums of a few dozen values of order 1

double Degrees(double radians) { return radians * 180.0 / std::numbers::pi; }

using testing::CameraToTheLeft;

// A corrugation along x whose top touches the face: z(x) = A (sin(2 pi x / P) - 1) <= 0 (mm).
struct Corrugation {
  double amplitude_mm = 0.08, period_mm = 0.4;
  double Height(double x) const { return amplitude_mm * (std::sin(2.0 * std::numbers::pi * x / period_mm) - 1.0); }
  double Slope(double x) const {
    return amplitude_mm * 2.0 * std::numbers::pi / period_mm * std::cos(2.0 * std::numbers::pi * x / period_mm);
  }
  // The mean height over [a, b] in plan, exactly.
  double MeanHeight(double a, double b) const {
    const double w = 2.0 * std::numbers::pi / period_mm;
    return amplitude_mm * (-(std::cos(w * b) - std::cos(w * a)) / w / (b - a) - 1.0);
  }
};

// What the finer grid holds of `surface` seen along `parallax`'s rays: each fine pixel the height
// and unit normal of the point its ray reaches, x_s = x_g + z(x_s) t (a fixed point: |z' t| <= 0.26
// here), and its share of the surface's plan (fine_grid.h SurfaceAreaWeights).
struct SeenAlongTheRays {
  Image height, normals, weights;
};
SeenAlongTheRays Seen(const Corrugation& surface, const reconstruction::ViewParallax& parallax, int width, int rows,
                      double fine_pitch) {
  SeenAlongTheRays seen{Image(width, rows, 1, 0.0f, fine_pitch), Image(width, rows, 3, 0.0f, fine_pitch), Image()};
  for (int c = 0; c < width; ++c) {
    const double x_grid = (c + 0.5) * fine_pitch;
    const double t = (parallax.camera_x_mm - x_grid) / (parallax.camera_z_mm - parallax.plane_z_mm);
    double x_seen = x_grid;
    for (int i = 0; i < 80; ++i) x_seen = x_grid + surface.Height(x_seen) * t;
    const double slope = surface.Slope(x_seen), length = std::sqrt(1.0 + slope * slope);
    for (int r = 0; r < rows; ++r) {
      seen.height.at(0, r, c) = static_cast<float>(surface.Height(x_seen));
      seen.normals.at(0, r, c) = static_cast<float>(-slope / length);
      seen.normals.at(2, r, c) = static_cast<float>(1.0 / length);
    }
  }
  seen.weights = SurfaceAreaWeights(seen.normals, parallax);
  return seen;
}

TEST(PlanPlacement, IsOffWithoutParallaxOrHeightsAndThenChangesNothing) {
  Image fine(8, 4, 2, 0.0f, 0.025);
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 8; ++c) fine.at(0, r, c) = static_cast<float>(c * c + r), fine.at(1, r, c) = static_cast<float>(r - c);
  }
  const Image heights(8, 4, 1, -0.05f, 0.025);
  EXPECT_FALSE(PlanPlacement().enabled());
  EXPECT_FALSE(PlanPlacement(heights, Image(), reconstruction::ViewParallax{}, 4).enabled());
  EXPECT_FALSE(PlanPlacement(Image(), Image(), CameraToTheLeft(), 4).enabled());
  const Image placed = PlacedWeightedMean(fine, Image(), PlanPlacement(), 4, 0.1);
  const Image block = BlockWeightedMean(fine, Image(), 4, 0.1);
  ASSERT_EQ(placed.width(), 2);
  ASSERT_EQ(placed.height(), 1);
  for (int ch = 0; ch < 2; ++ch) {
    for (int c = 0; c < 2; ++c) EXPECT_EQ(placed.at(ch, 0, c), block.at(ch, 0, c)) << ch << ", " << c;
  }
}

TEST(PlanPlacement, APointBelowTheTopMovesAwayFromTheCameraByItsDepthTimesTheLean) {
  const double fine_pitch = 0.02;
  Image heights(100, 4, 1, 0.5f, fine_pitch);  // up to a constant: the top (0.5) lies on the face
  heights.at(0, 1, 50) = 0.5f - 0.1f;          // 0.1 mm deep
  reconstruction::ViewParallax parallax = CameraToTheLeft();
  parallax.camera_y_mm = 30.0;  // and in front: the rays lean in y too
  const PlanPlacement placement(heights, Image(), parallax, 2);
  ASSERT_TRUE(placement.enabled());
  // x_s - x_g = (z - plane) t = -0.1 (camera - x_g).xy / 300; rows grow with -y. The low-pass
  // (kPlacementReliefSigmaMapPx) takes a lone pixel's depth for a drift by under 1 % of it.
  constexpr double kLowPassShare = 0.01;
  const double x = 50.5 * fine_pitch, y = -1.5 * fine_pitch;
  const double along_x = -0.1 * (-60.0 - x) / 300.0 / fine_pitch, along_y = 0.1 * (30.0 - y) / 300.0 / fine_pitch;
  float d_col = 1.0f, d_row = 1.0f;
  placement.OffsetFinePx(0, 0, &d_col, &d_row);  // on the top: where its ray met the face
  EXPECT_NEAR(d_col, 0.0f, kLowPassShare * std::abs(along_x));
  EXPECT_NEAR(d_row, 0.0f, kLowPassShare * std::abs(along_y));
  placement.OffsetFinePx(50, 1, &d_col, &d_row);
  EXPECT_NEAR(d_col, along_x, kLowPassShare * std::abs(along_x));
  EXPECT_NEAR(d_row, along_y, kLowPassShare * std::abs(along_y));
  EXPECT_GT(d_col, 0.0f);  // the camera is to the left: the point lies further right
  EXPECT_EQ(placement.margin_fine_px(), static_cast<int>(std::ceil(placement.largest_offset_fine_px())));
  EXPECT_GE(placement.largest_offset_fine_px(), std::hypot(d_col, d_row) - kFloatExact);
}

TEST(PlanPlacement, ASpikeMovesNoFurtherThanTheLimit) {
  Image heights(4, 4, 1, 0.0f, 0.01);
  heights.at(0, 2, 2) = -1000.0f;  // an integration spike, a metre deep
  const PlanPlacement placement(heights, Image(), CameraToTheLeft(), 2);
  float d_col = 0.0f, d_row = 0.0f;
  placement.OffsetFinePx(2, 2, &d_col, &d_row);
  EXPECT_NEAR(d_col, kMaxPlanOffsetMapPx * 2, kFloatExact);
  EXPECT_LE(placement.margin_fine_px(), static_cast<int>(std::ceil(kMaxPlanOffsetMapPx * 2)));
}

// Integrated heights on 160 x 160 map pixels of 0.04 mm at k = 2: a bowl rising `bowl_mm` from the
// centre to each edge's middle (an integration's drift, or the sample's sag), and, when
// `hollow_mm` > 0, one hollow of the fabric that deep, a Gaussian of 12 map pixels wide (a
// velvet's crushed pile) centred on map pixel (50, 100). The rest lies on the face.
constexpr int kBowlMaps = 160, kBowlK = 2, kHollowCol = 50, kHollowRow = 100;
constexpr double kBowlFinePitchMm = 0.02, kHollowSigmaMapPx = 12.0;
Image BowlWithAHollow(double bowl_mm, double hollow_mm) {
  Image heights(kBowlMaps * kBowlK, kBowlMaps * kBowlK, 1, 0.0f, kBowlFinePitchMm);
  const double half = kBowlMaps * kBowlK / 2.0;
  for (int r = 0; r < heights.height(); ++r) {
    for (int c = 0; c < heights.width(); ++c) {
      const double u = (c + 0.5) / half - 1.0, v = (r + 0.5) / half - 1.0;
      const double du = (c + 0.5) / kBowlK - (kHollowCol + 0.5), dv = (r + 0.5) / kBowlK - (kHollowRow + 0.5);
      const double hollow = hollow_mm * std::exp(-(du * du + dv * dv) / (2.0 * kHollowSigmaMapPx * kHollowSigmaMapPx));
      heights.at(0, r, c) = static_cast<float>(bowl_mm * (u * u + v * v) - hollow);
    }
  }
  return heights;
}

// The offset along x of a fine pixel `below_mm` under the face, seen by CameraToTheLeft (fine
// pixels; its rows do not lean).
double ExpectedColOffset(int col, double below_mm) {
  const reconstruction::ViewParallax parallax = CameraToTheLeft();
  return below_mm * (parallax.camera_x_mm - (col + 0.5) * kBowlFinePitchMm) / parallax.camera_z_mm / kBowlFinePitchMm;
}

TEST(PlanPlacement, TheHeightsBowlIsNotDepth) {
  constexpr double kBowlMm = 0.1;
  const PlanPlacement placement(BowlWithAHollow(kBowlMm, 0.0), Image(), CameraToTheLeft(), kBowlK);
  ASSERT_TRUE(placement.enabled());
  // Read as depth, the bowl would move a corner (0.2 mm up it) by 2.2 fine pixels. The quadratic
  // is taken out whole: measured 0.007 fine px at most (float sums of the fit).
  const int last = kBowlMaps * kBowlK - 1;
  const double bowl_as_depth = std::abs(ExpectedColOffset(last, 2.0 * kBowlMm));
  constexpr double kBowlShare = 0.02;
  double largest = 0.0;
  for (int row = 0; row <= last; ++row) {
    for (int col = 0; col <= last; ++col) {
      float d_col = 0.0f, d_row = 0.0f;
      placement.OffsetFinePx(col, row, &d_col, &d_row);
      largest = std::max({largest, std::abs(static_cast<double>(d_col)), std::abs(static_cast<double>(d_row))});
    }
  }
  std::cout << "[ MEASURED ] largest offset " << largest << " fine px (the bowl as depth: " << bowl_as_depth << ")\n";
  EXPECT_LT(largest, kBowlShare * bowl_as_depth);
}

TEST(PlanPlacement, AWideHollowKeepsItsDepth) {
  constexpr double kHollowMm = 0.05;
  const PlanPlacement placement(BowlWithAHollow(0.1, kHollowMm), Image(), CameraToTheLeft(), kBowlK);
  ASSERT_TRUE(placement.enabled());
  const int col = kHollowCol * kBowlK, row = kHollowRow * kBowlK;
  float d_col = 0.0f, d_row = 0.0f;
  placement.OffsetFinePx(col, row, &d_col, &d_row);
  const double expected = ExpectedColOffset(col, -kHollowMm);
  std::cout << "[ MEASURED ] the hollow's centre moves " << d_col << " fine px for " << expected << "\n";
  // The quadratic and the low-pass take a little of it: its share of the quadratic's fit and what
  // of it a sigma of 64 map pixels passes (measured 2 %); a sigma of 16 alone took a third.
  constexpr double kKeptDepthShare = 0.9;
  EXPECT_GT(d_col / expected, kKeptDepthShare);
  EXPECT_LT(d_col / expected, 1.0 + 1e-3);
}

TEST(PlacedWeightedMean, PutsACorrugationSeenAlongTheRaysBackOnThePlan) {
  // 12 map pixels of 0.1 mm, 8 fine pixels each; the valleys, 0.16 mm deep, move by up to 0.032 mm
  // (a third of a map pixel) away from the camera. Each map pixel's placed mean height is compared
  // with the plan's exact mean, and its placed mean unit normal with the plan's (a dense midpoint
  // sum), away from the two border pixels that the moved squares leave partly uncovered.
  const reconstruction::ViewParallax parallax = CameraToTheLeft();
  constexpr int kMaps = 12, kFine = 8, kRows = 2;
  constexpr double kPitchMm = 0.1;
  const Corrugation surface;
  const SeenAlongTheRays seen = Seen(surface, parallax, kMaps * kFine, kRows * kFine, kPitchMm / kFine);
  ASSERT_FALSE(seen.weights.empty());
  const PlanPlacement placement(seen.height, Image(), parallax, kFine);
  ASSERT_TRUE(placement.enabled());
  EXPECT_GE(placement.largest_offset_fine_px(), 2.0);

  // The squares are moved whole, though a pixel's plan length is 1 / stretch of it: measured 0.8 um
  // and 0.34 deg at worst on these slopes (up to 52 deg), against 19 um and 17 deg where the rays
  // met the grid. Tolerances: 1 % of the 0.16 mm range, and half a degree.
  constexpr double kHeightToleranceMm = 1.6e-3;
  constexpr double kNormalToleranceDeg = 0.5;
  const Image placed_height = PlacedWeightedMean(seen.height, seen.weights, placement, kFine, kPitchMm);
  const Image grid_height = BlockWeightedMean(seen.height, seen.weights, kFine, kPitchMm);
  const Image placed_normals = AverageNormalsOntoMaps(seen.normals, kFine, kPitchMm, seen.weights, placement);
  const Image grid_normals = AverageNormalsOntoMaps(seen.normals, kFine, kPitchMm, seen.weights);
  double worst_grid_height = 0.0, worst_grid_normal = 0.0;
  for (int c = 1; c + 1 < kMaps; ++c) {
    const double a = c * kPitchMm, b = a + kPitchMm;
    const double truth_height = surface.MeanHeight(a, b);
    Eigen::Vector3d truth_normal = Eigen::Vector3d::Zero();
    constexpr int kSamples = 4000;
    for (int i = 0; i < kSamples; ++i) {
      const double s = surface.Slope(a + (i + 0.5) * kPitchMm / kSamples);
      truth_normal += Eigen::Vector3d(-s, 0.0, 1.0).normalized();
    }
    truth_normal.normalize();
    auto angle = [&](const Image& n) {
      const Eigen::Vector3d v(n.at(0, 0, c), n.at(1, 0, c), n.at(2, 0, c));
      return Degrees(std::acos(std::clamp(v.normalized().dot(truth_normal), -1.0, 1.0)));
    };
    for (int r = 0; r < kRows; ++r) {
      EXPECT_NEAR(placed_height.at(0, r, c), truth_height, kHeightToleranceMm) << c;
    }
    EXPECT_LT(angle(placed_normals), kNormalToleranceDeg) << c;
    worst_grid_height = std::max(worst_grid_height, std::abs(grid_height.at(0, 0, c) - truth_height));
    worst_grid_normal = std::max(worst_grid_normal, angle(grid_normals));
  }
  // Where the rays met the grid, the same averages are off by several times that.
  EXPECT_GT(worst_grid_height, 4.0 * kHeightToleranceMm);
  EXPECT_GT(worst_grid_normal, 4.0 * kNormalToleranceDeg);
}

TEST(AveragePhotometricStereoOntoMaps, PlacesTheNormalsAlbedoAndHeightsAsThePlacedMeans) {
  // The photometric-stereo result of the finer grid (what `reconstruct` writes, and the maps' fit
  // starts from) goes onto the maps through the same placement as the fit's refined normals: its
  // normals are AverageNormalsOntoMaps', its albedo and heights PlacedWeightedMean's, each with the
  // surface weights of its own normals. The corrugation of the test above, seen along the rays.
  const reconstruction::ViewParallax parallax = CameraToTheLeft();
  constexpr int kMaps = 12, kFine = 8, kRows = 2;
  constexpr double kPitchMm = 0.1;
  const SeenAlongTheRays seen = Seen(Corrugation(), parallax, kMaps * kFine, kRows * kFine, kPitchMm / kFine);
  reconstruction::PhotometricStereoResult fine;
  fine.normal = seen.normals;
  fine.height_mm = seen.height;
  fine.albedo = Image(kMaps * kFine, kRows * kFine, 3, 0.0f, kPitchMm / kFine);
  for (int r = 0; r < kRows * kFine; ++r) {
    for (int c = 0; c < kMaps * kFine; ++c) {
      for (int ch = 0; ch < 3; ++ch) fine.albedo.at(ch, r, c) = static_cast<float>(0.2 + 0.1 * ch + 0.004 * c);
    }
  }
  fine.confidence = Image(kMaps * kFine, kRows * kFine, 1, 1.0f, kPitchMm / kFine);
  fine.condition_number = Image(kMaps * kFine, kRows * kFine, 1, 2.0f, kPitchMm / kFine);
  fine.used_lights = Image(kMaps * kFine, kRows * kFine, 1, 8.0f, kPitchMm / kFine);
  const PlanPlacement placement(seen.height, Image(), parallax, kFine);
  ASSERT_TRUE(placement.enabled());
  const reconstruction::PhotometricStereoResult placed =
      AveragePhotometricStereoOntoMaps(fine, kFine, kPitchMm, parallax, 0, placement);
  const reconstruction::PhotometricStereoResult on_rays = AveragePhotometricStereoOntoMaps(fine, kFine, kPitchMm, parallax);
  const Image normals = AverageNormalsOntoMaps(seen.normals, kFine, kPitchMm, seen.weights, placement);
  const Image albedo = PlacedWeightedMean(fine.albedo, seen.weights, placement, kFine, kPitchMm);
  const Image height = PlacedWeightedMean(seen.height, seen.weights, placement, kFine, kPitchMm);
  double moved = 0.0;  // how far the placement moved the heights from the average along the rays
  for (int r = 0; r < kRows; ++r) {
    for (int c = 0; c < kMaps; ++c) {
      for (int ch = 0; ch < 3; ++ch) {
        EXPECT_NEAR(placed.normal.at(ch, r, c), normals.at(ch, r, c), kFloatExact) << r << ", " << c;
        EXPECT_NEAR(placed.albedo.at(ch, r, c), albedo.at(ch, r, c), kFloatExact) << r << ", " << c;
      }
      EXPECT_NEAR(placed.height_mm.at(0, r, c), height.at(0, r, c), kFloatExact) << r << ", " << c;
      moved = std::max(moved, static_cast<double>(std::abs(placed.height_mm.at(0, r, c) - on_rays.height_mm.at(0, r, c))));
    }
  }
  // The test above: along the rays the heights are off the plan's by several um (> 6.4 um there).
  constexpr double kMovedAtLeastMm = 1e-3;
  EXPECT_GT(moved, kMovedAtLeastMm);
  // A band's rows (fine_row0 > 0) cannot take the whole grid's placement.
  EXPECT_THROW(AveragePhotometricStereoOntoMaps(fine, kFine, kPitchMm, parallax, kFine, placement), std::invalid_argument);
}

TEST(PlacedWeightedMean, RefusesAPlacementMadeForAnotherGrid) {
  const Image heights(8, 8, 1, 0.0f, 0.01);
  const PlanPlacement placement(heights, Image(), CameraToTheLeft(), 2);
  ASSERT_TRUE(placement.enabled());
  const Image fine(8, 8, 1, 1.0f, 0.01);
  EXPECT_THROW(PlacedWeightedMean(fine, Image(), placement, 4, 0.04), std::invalid_argument);
  EXPECT_THROW(PlacedWeightedMean(Image(4, 8, 1, 1.0f, 0.01), Image(), placement, 2, 0.02), std::invalid_argument);
  EXPECT_NO_THROW(PlacedWeightedMean(fine, Image(), placement, 2, 0.02));
}

TEST(FineColourAverage, PlacedInBandsAgreesWithThePlacedMean) {
  // The base colour accumulates band by band, spreading each fine pixel over the map pixels its
  // moved square overlaps; PlacedWeightedMean gathers the same shares for each map pixel.
  const reconstruction::ViewParallax parallax = CameraToTheLeft();
  constexpr int kMaps = 6, kFine = 4, kRows = 3;
  const Corrugation surface{0.05, 0.13};
  const SeenAlongTheRays seen = Seen(surface, parallax, kMaps * kFine, kRows * kFine, 0.1 / kFine);
  const PlanPlacement placement(seen.height, Image(), parallax, kFine);
  ASSERT_TRUE(placement.enabled());
  Image colour(kMaps * kFine, kRows * kFine, 3, 0.0f, 0.1 / kFine);
  for (int r = 0; r < colour.height(); ++r) {
    for (int c = 0; c < colour.width(); ++c) {
      colour.at(0, r, c) = 0.1f + 0.02f * static_cast<float>(c % 7);
      colour.at(1, r, c) = 0.5f - 0.01f * static_cast<float>(r);
      colour.at(2, r, c) = seen.height.at(0, r, c) + 0.3f;
    }
  }
  const Image clusters(colour.width(), colour.height(), 1, 0.0f, colour.pitch_mm());
  FineColourAverage average(kMaps, kRows, kFine);
  const int band_rows = 5;  // bands that do not follow the map rows
  for (int row0 = 0; row0 < colour.height(); row0 += band_rows) {
    const int rows = std::min(band_rows, colour.height() - row0);
    Image band_colour(colour.width(), rows, 3, 0.0f, colour.pitch_mm());
    Image band_weights(colour.width(), rows, 1, 0.0f, colour.pitch_mm());
    for (int r = 0; r < rows; ++r) {
      for (int c = 0; c < colour.width(); ++c) {
        for (int ch = 0; ch < 3; ++ch) band_colour.at(ch, r, c) = colour.at(ch, row0 + r, c);
        band_weights.at(0, r, c) = seen.weights.at(0, row0 + r, c);
      }
    }
    average.Add(band_colour, Image(colour.width(), rows, 1, 0.0f, colour.pitch_mm()), row0, band_weights, placement);
  }
  Image maps(kMaps, kRows, 3, -1.0f, 0.1);
  EXPECT_EQ(average.ApplyTo(Image(kMaps, kRows, 1, 0.0f, 0.1), &maps), kMaps * kRows);
  const Image gathered = PlacedWeightedMean(colour, seen.weights, placement, kFine, 0.1);
  const Image on_grid = BlockWeightedMean(colour, seen.weights, kFine, 0.1);
  double largest_move = 0.0;
  for (int r = 0; r < kRows; ++r) {
    for (int c = 0; c < kMaps; ++c) {
      for (int ch = 0; ch < 3; ++ch) {
        EXPECT_NEAR(maps.at(ch, r, c), gathered.at(ch, r, c), kFloatExact) << ch << " at " << r << ", " << c;
        largest_move = std::max(largest_move, std::abs(static_cast<double>(maps.at(ch, r, c) - on_grid.at(ch, r, c))));
      }
    }
  }
  EXPECT_GT(largest_move, 100 * kFloatExact);  // the placement did move the colours
  EXPECT_THROW(average.Add(colour, clusters, 0, seen.weights, PlanPlacement(seen.height, Image(), parallax, 2)),
               std::invalid_argument);
}

}  // namespace
}  // namespace u3mscan
