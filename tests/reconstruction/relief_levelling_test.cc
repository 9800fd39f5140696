#include "reconstruction/relief_levelling.h"

#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <limits>
#include <numbers>
#include <stdexcept>

#include "tests/support/analytic_surface.h"

namespace u3mscan::reconstruction {
namespace {

constexpr double kPitchMm = 0.1;
constexpr int kSide = 128;  // 12.8 mm
// A texture of 0.02 mm amplitude, wavelength 1 mm (12.8 periods over the map): what of it the
// quadratic basis explains is left out with the bowl. Measured 0.2 um RMS of leakage; the bound
// is 1 um against the 14-38 um RMS of the tilt and bowl added.
constexpr double kTextureLeakageRmsMm = 0.001;
constexpr double kTextureAmplitudeMm = 0.02;
constexpr double kTextureWavelengthMm = 1.0;
// A tilt of 0.01 (0.57 deg) and a bowl of 0.2 um/mm^2 (36 um over the map's half diagonal).
constexpr double kTiltX = 0.01, kTiltY = -0.006, kBowl = 0.0002;
// The recovered bowl and tilt, relative to what was added (the texture's leakage).
constexpr double kCoefficientRelativeTolerance = 0.02;
// Normals turned by the removed tilt against the analytic normals of the surface without it:
// rotating a normal is not subtracting a slope; the two differ by up to the product of the tilt
// (0.012) and the texture's slope (<= 0.13 here), 0.085 deg. Measured 0.024 deg at most.
constexpr double kNormalToleranceDeg = 0.05;

using Surface = testing::AnalyticSurface;

double X(int col) { return testing::GridX(col, kPitchMm); }
double Y(int row) { return testing::GridY(row, kPitchMm); }  // rows grow with -y
double CentreX() { return X(0) + 0.5 * (kSide - 1) * kPitchMm; }
double CentreY() { return Y(0) - 0.5 * (kSide - 1) * kPitchMm; }

Surface Texture() {
  const double k = 2.0 * std::numbers::pi / kTextureWavelengthMm;
  return {[k](double x, double y) { return kTextureAmplitudeMm * std::sin(k * x) * std::sin(k * y); },
          [k](double x, double y) { return kTextureAmplitudeMm * k * std::cos(k * x) * std::sin(k * y); },
          [k](double x, double y) { return kTextureAmplitudeMm * k * std::sin(k * x) * std::cos(k * y); }};
}

// The texture plus a tilt and a bowl about the map's centre (`bowl` 0: only the tilt).
Surface Shaped(double tilt_x, double tilt_y, double bowl) {
  const Surface t = Texture();
  return {[=](double x, double y) {
            const double u = x - CentreX(), v = y - CentreY();
            return t.z(x, y) + tilt_x * u + tilt_y * v + bowl * (u * u + v * v);
          },
          [=](double x, double y) { return t.dzdx(x, y) + tilt_x + 2.0 * bowl * (x - CentreX()); },
          [=](double x, double y) { return t.dzdy(x, y) + tilt_y + 2.0 * bowl * (y - CentreY()); }};
}

Image HeightOf(const Surface& s) {
  Image h(kSide, kSide, 1, 0.0f, kPitchMm);
  for (int r = 0; r < kSide; ++r)
    for (int c = 0; c < kSide; ++c) h.at(0, r, c) = static_cast<float>(s.z(X(c), Y(r)));
  return h;
}

Image NormalsOf(const Surface& s) { return testing::NormalsOfSurface(s, kSide, kSide, kPitchMm); }

// RMS of (a - b) after removing the mean difference, over pixels where `weight` > 0 (empty: all).
double RmsDifference(const Image& a, const Image& b, const Image& weight = Image()) {
  double sum = 0.0, sum2 = 0.0, n = 0.0;
  for (int r = 0; r < a.height(); ++r)
    for (int c = 0; c < a.width(); ++c) {
      if (!weight.empty() && !(weight.at(0, r, c) > 0.0f)) continue;
      const double d = static_cast<double>(a.at(0, r, c)) - b.at(0, r, c);
      sum += d, sum2 += d * d, n += 1.0;
    }
  return std::sqrt(std::max(0.0, sum2 / n - (sum / n) * (sum / n)));
}

double MaxAngleDeg(const Image& a, const Image& b) {
  double worst = 0.0;
  for (int r = 0; r < a.height(); ++r)
    for (int c = 0; c < a.width(); ++c) {
      double dot = 0.0;
      for (int ch = 0; ch < 3; ++ch) dot += static_cast<double>(a.at(ch, r, c)) * b.at(ch, r, c);
      worst = std::max(worst, std::acos(std::clamp(dot, -1.0, 1.0)) * 180.0 / std::numbers::pi);
    }
  return worst;
}

double Mean(const Image& image) { return image.ChannelMean(0); }

TEST(ReliefLevelling, QuadraticTakesOutTheTiltAndTheBowlAndKeepsTheTexture) {
  const Image texture = HeightOf(Texture());
  Image height = HeightOf(Shaped(kTiltX, kTiltY, kBowl));
  const double before = RmsDifference(height, texture);
  ASSERT_GT(before, 10.0 * kTextureLeakageRmsMm) << "the shape added must be far above the bound";
  const double mean_before = Mean(height);

  const LevellingResult removed = LevelRelief(Levelling::kQuadratic, &height, nullptr);
  EXPECT_LT(RmsDifference(height, texture), kTextureLeakageRmsMm);
  EXPECT_NEAR(Mean(height), mean_before, 1e-6) << "the mean height is kept";
  // In the result's units: u = (x - centre) / half width, so the bowl's u^2 term is kBowl * half^2.
  const double half_mm = 0.5 * kSide * kPitchMm;
  EXPECT_NEAR(removed.coefficients_mm[1], kTiltX * half_mm, kCoefficientRelativeTolerance * kTiltX * half_mm);
  EXPECT_NEAR(removed.coefficients_mm[2], -kTiltY * half_mm, kCoefficientRelativeTolerance * std::abs(kTiltY) * half_mm)
      << "v grows with the rows, against y";
  EXPECT_NEAR(removed.coefficients_mm[3], kBowl * half_mm * half_mm, kCoefficientRelativeTolerance * kBowl * half_mm * half_mm);
  EXPECT_NEAR(removed.coefficients_mm[5], kBowl * half_mm * half_mm, kCoefficientRelativeTolerance * kBowl * half_mm * half_mm);
  EXPECT_NEAR(removed.coefficients_mm[4], 0.0, kCoefficientRelativeTolerance * kBowl * half_mm * half_mm);
  EXPECT_NEAR(removed.max_tilt_deg,
              std::atan(std::hypot(std::abs(kTiltX) + 2.0 * kBowl * half_mm, std::abs(kTiltY) + 2.0 * kBowl * half_mm)) * 180.0 /
                  std::numbers::pi,
              0.05);
  EXPECT_GT(removed.peak_to_valley_mm, 0.0);
  EXPECT_EQ(removed.weighted_pixels, static_cast<double>(kSide * kSide));
}

TEST(ReliefLevelling, PlaneTakesOutTheTiltAndLeavesTheBowl) {
  const Image with_bowl = HeightOf(Shaped(0.0, 0.0, kBowl));
  Image height = HeightOf(Shaped(kTiltX, kTiltY, kBowl));
  const LevellingResult removed = LevelRelief(Levelling::kPlane, &height, nullptr);
  EXPECT_LT(RmsDifference(height, with_bowl), kTextureLeakageRmsMm);
  EXPECT_EQ(removed.coefficients_mm[3], 0.0);
  EXPECT_EQ(removed.coefficients_mm[5], 0.0);
}

TEST(ReliefLevelling, NormalsTurnByTheTiltNotByTheBowl) {
  const Surface shaped = Shaped(kTiltX, kTiltY, kBowl);
  Image height = HeightOf(shaped);
  Image normal = NormalsOf(shaped);
  const Image expected = NormalsOf(Shaped(0.0, 0.0, kBowl));
  ASSERT_GT(MaxAngleDeg(normal, expected), 0.5) << "the tilt must be seen in the normals before";
  LevelRelief(Levelling::kQuadratic, &height, &normal);
  EXPECT_LT(MaxAngleDeg(normal, expected), kNormalToleranceDeg);
  for (int r = 0; r < kSide; ++r)
    for (int c = 0; c < kSide; ++c) {
      const double length = std::hypot(normal.at(0, r, c), normal.at(1, r, c), normal.at(2, r, c));
      ASSERT_NEAR(length, 1.0, 1e-5) << "at " << r << ", " << c;
    }
}

TEST(ReliefLevelling, PixelsOffTheSampleDoNotMoveTheFitAndNonFiniteHeightsStay) {
  const Image texture = HeightOf(Texture());
  Image height = HeightOf(Shaped(kTiltX, kTiltY, kBowl));
  Image weight(kSide, kSide, 1, 1.0f, kPitchMm);
  // A hole in the corner reads the table 5 mm down, and one pixel is not a number.
  for (int r = 0; r < 30; ++r)
    for (int c = 0; c < 40; ++c) {
      height.at(0, r, c) = -5.0f;
      weight.at(0, r, c) = 0.0f;
    }
  height.at(0, 100, 100) = std::numeric_limits<float>::quiet_NaN();
  LevelRelief(Levelling::kQuadratic, &height, nullptr, weight);
  EXPECT_TRUE(std::isnan(height.at(0, 100, 100)));
  height.at(0, 100, 100) = texture.at(0, 100, 100);
  EXPECT_LT(RmsDifference(height, texture, weight), kTextureLeakageRmsMm);

  // The same without the weights: the hole pulls the fit.
  Image unweighted = HeightOf(Shaped(kTiltX, kTiltY, kBowl));
  for (int r = 0; r < 30; ++r)
    for (int c = 0; c < 40; ++c) unweighted.at(0, r, c) = -5.0f;
  LevelRelief(Levelling::kQuadratic, &unweighted, nullptr);
  EXPECT_GT(RmsDifference(unweighted, texture, weight), 10.0 * kTextureLeakageRmsMm);
}

TEST(ReliefLevelling, NoneOrTooFewPixelsChangeNothing) {
  const Image original = HeightOf(Shaped(kTiltX, kTiltY, kBowl));
  const Image original_normal = NormalsOf(Shaped(kTiltX, kTiltY, kBowl));
  Image height = original, normal = original_normal;
  EXPECT_EQ(LevelRelief(Levelling::kNone, &height, &normal).weighted_pixels, 0.0);
  EXPECT_EQ(height.data(), original.data());
  EXPECT_EQ(normal.data(), original_normal.data());

  // One valid row fixes a tilt along it but no bowl across it.
  Image one_row(kSide, kSide, 1, 0.0f, kPitchMm);
  for (int c = 0; c < kSide; ++c) one_row.at(0, 64, c) = 1.0f;
  EXPECT_EQ(LevelRelief(Levelling::kQuadratic, &height, &normal, one_row).weighted_pixels, 0.0);
  EXPECT_EQ(height.data(), original.data());
  EXPECT_EQ(normal.data(), original_normal.data());
}

TEST(ReliefLevelling, NamesAndSizesAreChecked) {
  for (Levelling l : {Levelling::kNone, Levelling::kPlane, Levelling::kQuadratic}) {
    EXPECT_EQ(ParseLevelling(LevellingName(l)), l);
  }
  EXPECT_THROW(ParseLevelling("cubic"), std::invalid_argument);
  Image height(8, 8, 1, 0.0f, kPitchMm), wrong_normal(8, 7, 3, 0.0f, kPitchMm), wrong_weight(7, 8, 1, 1.0f, kPitchMm);
  EXPECT_THROW(LevelRelief(Levelling::kPlane, &height, &wrong_normal), std::invalid_argument);
  EXPECT_THROW(LevelRelief(Levelling::kPlane, &height, nullptr, wrong_weight), std::invalid_argument);
  EXPECT_THROW(LevelRelief(Levelling::kPlane, nullptr, nullptr), std::invalid_argument);
}

}  // namespace
}  // namespace u3mscan::reconstruction
