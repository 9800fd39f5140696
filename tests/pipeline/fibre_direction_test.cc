#include "pipeline/fibre_direction.h"

#include <gtest/gtest.h>

#include <Eigen/Core>
#include <cmath>
#include <functional>
#include <stdexcept>

#include "fitting/shading_frame.h"

namespace u3mscan {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kPitchMm = 0.02;
constexpr int kSize = 96;
// The turned tangent lies along the fibres within this angle (the window averages the tensor over a
// few pixels of a field whose direction is the same everywhere: only rounding is left).
constexpr double kStraightFibreToleranceDeg = 1.0;
// On a ring the direction turns within the window: a little more.
constexpr double kRingFibreToleranceDeg = 3.0;

// Normal map of the height field h(x, y) mm (world x right, y up; rows grow with -y), from its
// analytic gradient.
using Gradient = std::function<Eigen::Vector2d(double x_mm, double y_mm)>;
Image NormalsOf(const Gradient& gradient) {
  Image normals(kSize, kSize, 3, 0.0f, kPitchMm);
  for (int row = 0; row < kSize; ++row) {
    for (int col = 0; col < kSize; ++col) {
      const Eigen::Vector2d g = gradient((col + 0.5) * kPitchMm, (kSize - row - 0.5) * kPitchMm);
      const Eigen::Vector3d n = Eigen::Vector3d(-g.x(), -g.y(), 1.0).normalized();
      for (int c = 0; c < 3; ++c) normals.at(c, row, col) = static_cast<float>(n(c));
    }
  }
  return normals;
}

Eigen::Vector3d NormalAt(const Image& normals, int row, int col) {
  return {normals.at(0, row, col), normals.at(1, row, col), normals.at(2, row, col)};
}

// Angle (deg) between the tangent the turn gives at (row, col) and the plan direction `fibre`,
// the stretch repeating every 180 degrees.
double TurnedTangentOffDeg(const Image& normals, const Image& turns, int row, int col, const Eigen::Vector3d& fibre) {
  const Eigen::Vector3d n = NormalAt(normals, row, col);
  const Eigen::Vector3d t = fitting::MakeShadingFrame(n, turns.at(0, row, col)).tangent;
  const Eigen::Vector3d f = (fibre - fibre.dot(n) * n).normalized();
  return std::acos(std::min(1.0, std::abs(t.dot(f)))) * 180.0 / kPi;
}

class StraightCords : public ::testing::TestWithParam<double> {};

// Cords along `fibre_deg` in plan (slopes up to 23 deg across them): every turned tangent runs
// along them.
TEST_P(StraightCords, TheTurnedTangentRunsAlongTheCords) {
  const double fibre_deg = GetParam(), a = fibre_deg * kPi / 180.0;
  const Eigen::Vector2d across(-std::sin(a), std::cos(a));
  constexpr double kAmplitudeMm = 0.02, kPeriodMm = 0.3;
  const Image normals = NormalsOf([&](double x, double y) {
    const double u = across.dot(Eigen::Vector2d(x, y));
    return Eigen::Vector2d(kAmplitudeMm * 2.0 * kPi / kPeriodMm * std::cos(2.0 * kPi * u / kPeriodMm) * across);
  });
  const Image turns = FibreTurnFromNormals(normals);
  ASSERT_EQ(turns.channels(), 1);
  ASSERT_EQ(turns.width(), kSize);
  EXPECT_EQ(turns.pitch_mm(), kPitchMm);
  const Eigen::Vector3d fibre(std::cos(a), std::sin(a), 0.0);
  double worst = 0.0;
  for (int row = 4; row < kSize - 4; ++row) {
    for (int col = 4; col < kSize - 4; ++col) {
      const float turn = turns.at(0, row, col);
      ASSERT_TRUE(turn >= 0.0f && turn < 180.0f) << turn;
      worst = std::max(worst, TurnedTangentOffDeg(normals, turns, row, col, fibre));
    }
  }
  EXPECT_LT(worst, kStraightFibreToleranceDeg) << "cords at " << fibre_deg << " deg";
}

INSTANTIATE_TEST_SUITE_P(Directions, StraightCords, ::testing::Values(0.0, 30.0, 90.0, 150.0));

// A cord round a ring (a lace's gimp round its motif): on the cord's flanks the tangent follows
// the ring.
TEST(FibreTurnFromNormals, ACordRoundARingTurnsWithIt) {
  const Eigen::Vector2d centre(0.5 * kSize * kPitchMm, 0.5 * kSize * kPitchMm);
  constexpr double kRingMm = 0.6, kHalfWidthMm = 0.15, kHeightMm = 0.05;
  // h = H cos^2(pi d / (2 w)) for |d| < w, d the distance from the ring.
  const Image normals = NormalsOf([&](double x, double y) {
    const Eigen::Vector2d p = Eigen::Vector2d(x, y) - centre;
    const double r = p.norm(), d = r - kRingMm;
    if (std::abs(d) >= kHalfWidthMm || r == 0.0) return Eigen::Vector2d(0.0, 0.0);
    const double dh_dd = -kHeightMm * kPi / (2.0 * kHalfWidthMm) * std::sin(kPi * d / kHalfWidthMm);
    return Eigen::Vector2d(dh_dd * p / r);
  });
  const Image turns = FibreTurnFromNormals(normals);
  int checked = 0;
  for (int row = 0; row < kSize; ++row) {
    for (int col = 0; col < kSize; ++col) {
      const Eigen::Vector2d p =
          Eigen::Vector2d((col + 0.5) * kPitchMm, (kSize - row - 0.5) * kPitchMm) - centre;
      const double d = p.norm() - kRingMm;
      if (std::abs(d) > 0.6 * kHalfWidthMm || std::abs(d) < 0.2 * kHalfWidthMm) continue;  // the flanks
      const Eigen::Vector3d along(-p.y(), p.x(), 0.0);
      EXPECT_LT(TurnedTangentOffDeg(normals, turns, row, col, along.normalized()), kRingFibreToleranceDeg)
          << "pixel " << col << ", " << row;
      ++checked;
    }
  }
  EXPECT_GT(checked, 500);
}

// A plane, level or tilted, shows no fibres: every turn stays 0.
TEST(FibreTurnFromNormals, APlaneShowsNoDirection) {
  for (const Eigen::Vector2d& slope : {Eigen::Vector2d(0.0, 0.0), Eigen::Vector2d(0.3, -0.2)}) {
    const Image turns = FibreTurnFromNormals(NormalsOf([&](double, double) { return slope; }));
    for (float t : turns.plane(0)) ASSERT_EQ(t, 0.0f);
  }
}

// An egg-crate turns its normal as much one way as the other over the window: no direction where
// the tensor is not coherent (most pixels keep 0).
TEST(FibreTurnFromNormals, AnIsotropicReliefKeepsMostPixelsUnturned) {
  constexpr double kAmplitudeMm = 0.02, kPeriodMm = 0.16;
  const double k = 2.0 * kPi / kPeriodMm;
  const Image normals = NormalsOf([&](double x, double y) {
    return Eigen::Vector2d(kAmplitudeMm * k * std::cos(k * x) * std::sin(k * y),
                           kAmplitudeMm * k * std::sin(k * x) * std::cos(k * y));
  });
  FibreDirectionOptions wide;
  wide.window_px = 4.0;  // a window over about half a period
  const Image turns = FibreTurnFromNormals(normals, wide);
  int unturned = 0;
  for (float t : turns.plane(0)) unturned += t == 0.0f ? 1 : 0;
  EXPECT_GT(unturned, kSize * kSize / 2);
}

// Turns averaged onto a grid k times coarser as stretches (doubled angles): 10 and 170 degrees are
// 20 apart across the half turn and average to 0, not to their arithmetic 90.
TEST(AverageTurnsOntoMaps, AveragesStretchesAcrossTheHalfTurn) {
  constexpr int kFine = 3;
  Image fine(2 * kFine, kFine, 1, 0.0f, kPitchMm / kFine);
  for (int row = 0; row < kFine; ++row) {
    for (int col = 0; col < kFine; ++col) {
      fine.at(0, row, col) = 40.0f;                                // the first map pixel: one direction
      fine.at(0, row, kFine + col) = col % 2 == 0 ? 10.0f : 170.0f;  // the second: either side of 0
    }
  }
  const Image maps = AverageTurnsOntoMaps(fine, kFine, kPitchMm);
  ASSERT_EQ(maps.width(), 2);
  ASSERT_EQ(maps.height(), 1);
  EXPECT_EQ(maps.pitch_mm(), kPitchMm);
  EXPECT_NEAR(maps.at(0, 0, 0), 40.0, 1e-4);
  const double second = maps.at(0, 0, 1);
  EXPECT_LT(std::min(second, 180.0 - second), 5.0) << second;  // 5 at 10 and 4 at 170: about 1.1
  EXPECT_THROW(AverageTurnsOntoMaps(Image(4, 3, 1), 3, kPitchMm), std::invalid_argument);
  EXPECT_THROW(AverageTurnsOntoMaps(Image(3, 3, 3), 3, kPitchMm), std::invalid_argument);
}

TEST(FibreTurnFromNormals, RefusesAMapWithoutThreeChannelsAndInvalidOptions) {
  EXPECT_THROW(FibreTurnFromNormals(Image(8, 8, 1, 0.0f, kPitchMm)), std::invalid_argument);
  FibreDirectionOptions bad;
  bad.window_px = 0.0;
  EXPECT_THROW(FibreTurnFromNormals(Image(8, 8, 3, 0.0f, kPitchMm), bad), std::invalid_argument);
  bad = FibreDirectionOptions();
  bad.min_coherence = 1.5;
  EXPECT_THROW(FibreTurnFromNormals(Image(8, 8, 3, 0.0f, kPitchMm), bad), std::invalid_argument);
}

}  // namespace
}  // namespace u3mscan
