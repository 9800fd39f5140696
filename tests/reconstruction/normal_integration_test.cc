#include "reconstruction/normal_integration.h"

#include <gtest/gtest.h>

#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>

#include <cmath>
#include <cstdio>
#include <functional>
#include <numbers>
#include <random>
#include <vector>

#include "tests/support/analytic_surface.h"

namespace u3mscan::reconstruction {
namespace {

constexpr double kPitchMm = 0.1;
// Round trip of the DCT in double precision.
constexpr double kDctRoundTripTolerance = 1e-12;
// A paraboloid has linear slopes, so the trapezoid edge targets are exact: only round-off remains.
constexpr double kParaboloidToleranceMm = 1e-6;
// Paired (two lines per complex FFT) against single-line DCT: the same sums in another order.
constexpr double kDctPairTolerance = 1e-12;
// Weighted integration (PCG to the default relative residual 1e-7) against a direct sparse
// Cholesky solve of the same least-squares system, max |difference| on the valid pixels over the
// height range there: float32 heights (6e-8 relative) plus the CG stop; measured 2e-7 - 8e-7.
constexpr double kDirectSolveRelativeTolerance = 1e-5;
// The unmasked exact DCT solve against the same direct solve: float32 heights (measured 2.5e-8).
constexpr double kExactDirectRelativeTolerance = 1e-6;
// PCG iterations of one weighted solve at the awkward sizes below. The padded preconditioner
// needs 40-44 on these maps (the exact-size one 15-17; measured); the bound catches a
// preconditioner that stopped approximating the Laplacian (a mirrored pad took 178-252).
constexpr int kMaxWeightedCgIterations = 80;
// A sinusoid of wavelength 32 px: the discretisation error of the edge targets, relative to the
// height range (peak to peak).
constexpr double kSinusoidRelativeTolerance = 0.01;

using Surface = testing::AnalyticSurface;

double PixelX(int c) { return testing::GridX(c, kPitchMm); }
double PixelY(int r) { return testing::GridY(r, kPitchMm); }  // rows grow with -y

Image NormalsOf(const Surface& s, int w, int h) { return testing::NormalsOfSurface(s, w, h, kPitchMm); }

// RMS of (height - truth) after removing the mean difference, over pixels where mask > 0.
double RmsErrorMm(const Image& height, const Surface& s, const Image& mask = Image()) {
  double sum = 0.0, sum2 = 0.0, count = 0.0;
  for (int r = 0; r < height.height(); ++r)
    for (int c = 0; c < height.width(); ++c) {
      if (!mask.empty() && mask.at(0, r, c) <= 0.0f) continue;
      const double d = height.at(0, r, c) - s.z(PixelX(c), PixelY(r));
      sum += d, sum2 += d * d, count += 1.0;
    }
  const double mean = sum / count;
  return std::sqrt(std::max(0.0, sum2 / count - mean * mean));
}

Surface Paraboloid() {
  const double a = 0.05, xc = 3.0, yc = -2.5;
  return {[=](double x, double y) { return a * ((x - xc) * (x - xc) + (y - yc) * (y - yc)); },
          [=](double x, double) { return 2 * a * (x - xc); }, [=](double, double y) { return 2 * a * (y - yc); }};
}

Surface Sinusoid() {
  const double amp = 0.2, k = 2 * std::numbers::pi / (32 * kPitchMm);
  return {[=](double x, double y) { return amp * std::sin(k * x) * std::cos(k * y); },
          [=](double x, double y) { return amp * k * std::cos(k * x) * std::cos(k * y); },
          [=](double x, double y) { return -amp * k * std::sin(k * x) * std::sin(k * y); }};
}

bool AllFinite(const Image& image) {
  for (float v : image.data())
    if (!std::isfinite(v)) return false;
  return true;
}

TEST(Dct, InverseUndoesForwardAndMatchesTheDefinition) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> uni(-1.0, 1.0);
  for (int n : {1, 2, 3, 5, 8, 17, 64, 100, 97, 1181, 2 * 1009}) {  // 97, 1181, 1009: Bluestein
    std::vector<double> x(n), y;
    for (double& v : x) v = uni(rng);
    y = x;
    internal::DctLine(y.data(), n);
    for (int k = 0; k < n; ++k) {
      double expected = 0.0;
      for (int i = 0; i < n; ++i) expected += x[i] * std::cos(std::numbers::pi * k * (2 * i + 1) / (2.0 * n));
      ASSERT_NEAR(y[k], expected, 1e-8) << "n=" << n << " k=" << k;
    }
    internal::InverseDctLine(y.data(), n);
    for (int i = 0; i < n; ++i) ASSERT_NEAR(y[i], x[i], kDctRoundTripTolerance) << "n=" << n;
  }
}

TEST(Dct, PairedLinesMatchSingleLines) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> uni(-1.0, 1.0);
  for (int n : {1, 2, 3, 5, 8, 17, 64, 97, 211, 307, 3750}) {  // 97, 211, 307: Bluestein
    std::vector<double> a(n), b(n);
    for (double& v : a) v = uni(rng);
    for (double& v : b) v = uni(rng);
    std::vector<double> a1 = a, b1 = b, a2 = a, b2 = b;
    internal::DctLine(a1.data(), n);
    internal::DctLine(b1.data(), n);
    internal::DctLinePair(a2.data(), b2.data(), n);
    for (int k = 0; k < n; ++k) {
      ASSERT_NEAR(a2[k], a1[k], kDctPairTolerance * n) << "n=" << n << " k=" << k;
      ASSERT_NEAR(b2[k], b1[k], kDctPairTolerance * n) << "n=" << n << " k=" << k;
    }
    internal::InverseDctLinePair(a2.data(), b2.data(), n);
    for (int i = 0; i < n; ++i) {
      ASSERT_NEAR(a2[i], a[i], kDctPairTolerance) << "n=" << n << " i=" << i;
      ASSERT_NEAR(b2[i], b[i], kDctPairTolerance) << "n=" << n << " i=" << i;
    }
  }
}

TEST(Dct, SmoothLengthIsTheNextTwoThreeFiveSmoothLength) {
  auto smooth = [](int m) {
    for (int p : {2, 3, 5})
      while (m % p == 0) m /= p;
    return m == 1;
  };
  for (int n : {1, 2, 7, 211, 307, 921, 1380, 2456, 3684, 5520}) {
    const int m = internal::SmoothLength(n);
    EXPECT_GE(m, n);
    EXPECT_TRUE(smooth(m)) << n << " -> " << m;
    for (int k = n; k < m; ++k) EXPECT_FALSE(smooth(k)) << n << ": " << k << " is smooth";
  }
}

TEST(IntegrateNormals, SignConventionsFollowTheWorldFrame) {
  // Plane rising toward +x and +y: heights grow with the column and fall with the row.
  Surface plane{[](double x, double y) { return 0.3 * x + 0.2 * y; }, [](double, double) { return 0.3; },
                [](double, double) { return 0.2; }};
  const Image n = NormalsOf(plane, 16, 12);
  for (Integrator method : {Integrator::kDct, Integrator::kRobust}) {
    IntegrationOptions options;
    options.method = method;
    const IntegrationResult result = IntegrateNormals(n, Image(), options);
    EXPECT_NEAR(result.height_mm.at(0, 0, 1) - result.height_mm.at(0, 0, 0), 0.3 * kPitchMm, 1e-6);
    EXPECT_NEAR(result.height_mm.at(0, 1, 0) - result.height_mm.at(0, 0, 0), -0.2 * kPitchMm, 1e-6);
    EXPECT_NEAR(result.height_mm.ChannelMean(0), 0.0, 1e-6);  // anchored at mean_height_mm
  }
}

TEST(IntegrateNormals, RecoversParaboloidWithBothIntegrators) {
  const Surface s = Paraboloid();
  // 37 x 41: both sides prime, so the DCT runs through Bluestein's FFT.
  for (auto [w, h] : {std::pair{64, 48}, std::pair{37, 41}}) {
    const Image n = NormalsOf(s, w, h);
    for (Integrator method : {Integrator::kDct, Integrator::kRobust}) {
      IntegrationOptions options;
      options.method = method;
      const IntegrationResult result = IntegrateNormals(n, Image(), options);
      EXPECT_LT(RmsErrorMm(result.height_mm, s), kParaboloidToleranceMm) << IntegratorName(method) << " " << w << "x" << h;
    }
  }
}

TEST(IntegrateNormals, RecoversSinusoidWithBothIntegrators) {
  const Surface s = Sinusoid();
  const Image n = NormalsOf(s, 64, 64);
  const double range_mm = 0.4;
  for (Integrator method : {Integrator::kDct, Integrator::kRobust}) {
    IntegrationOptions options;
    options.method = method;
    const IntegrationResult result = IntegrateNormals(n, Image(), options);
    const double relative = RmsErrorMm(result.height_mm, s) / range_mm;
    std::printf("sinusoid 64x64: %s RMS height error %.5f of the range\n", IntegratorName(method).c_str(), relative);
    EXPECT_LT(relative, kSinusoidRelativeTolerance) << IntegratorName(method);
  }
}

// A camera 40 mm above a 12.8 mm map (rays up to 13 deg off vertical at the corners) sees each
// grid point of the plane z = 0 through the surface point its ray reaches first; the normal map
// holds those points' normals. Integrated along the grid as if the rays were vertical, the height
// leans toward the camera (a bowl of about E[s^2] t in slope); with ViewParallax it is the height
// of the points seen. Bounds: relative RMS (offset removed) of the range.
constexpr double kParallaxCorrectedTolerance = 0.01;
constexpr double kParallaxUncorrectedAtLeast = 0.03;  // measured 0.042 (corrected: 0.0032)

TEST(IntegrateNormals, ViewParallaxTakesTheCamerasRaysIntoAccount) {
  const double amp = 0.1, k = 2 * std::numbers::pi / (16 * kPitchMm);
  const Surface s{[=](double x, double y) { return amp * std::sin(k * x) * std::cos(k * y); },
                  [=](double x, double y) { return amp * k * std::cos(k * x) * std::cos(k * y); },
                  [=](double x, double y) { return -amp * k * std::sin(k * x) * std::sin(k * y); }};
  const int size = 128;
  const double cx = 0.5 * size * kPitchMm, cy = -0.5 * size * kPitchMm, cz = 40.0;
  Image normal(size, size, 3, 0.0f, kPitchMm);
  std::vector<double> seen_z(static_cast<std::size_t>(size) * size);
  for (int r = 0; r < size; ++r) {
    for (int c = 0; c < size; ++c) {
      // The ray from the camera through (gx, gy, 0) meets the surface where z(x, y) = cz (1 - t).
      const double gx = PixelX(c), gy = PixelY(r);
      double x = gx, y = gy;
      for (int it = 0; it < 50; ++it) {
        const double t = 1.0 - s.z(x, y) / cz;
        x = cx + t * (gx - cx), y = cy + t * (gy - cy);
      }
      const double px = -s.dzdx(x, y), py = -s.dzdy(x, y), len = std::sqrt(px * px + py * py + 1.0);
      normal.at(0, r, c) = static_cast<float>(px / len);
      normal.at(1, r, c) = static_cast<float>(py / len);
      normal.at(2, r, c) = static_cast<float>(1.0 / len);
      seen_z[static_cast<std::size_t>(r) * size + c] = s.z(x, y);
    }
  }
  auto relative_error = [&](bool parallax) {
    IntegrationOptions options;
    options.parallax.enabled = parallax;
    options.parallax.camera_x_mm = cx, options.parallax.camera_y_mm = cy, options.parallax.camera_z_mm = cz;
    const Image height = IntegrateNormals(normal, Image(), options).height_mm;
    double sum = 0.0, sum2 = 0.0;
    for (std::size_t i = 0; i < seen_z.size(); ++i) {
      const double d = height.data()[i] - seen_z[i];
      sum += d, sum2 += d * d;
    }
    const double mean = sum / seen_z.size();
    return std::sqrt(std::max(0.0, sum2 / seen_z.size() - mean * mean)) / (2.0 * amp);
  };
  const double corrected = relative_error(true), vertical = relative_error(false);
  std::printf("[ MEASURED ] height error of the range: rays taken as vertical %.4f, along the camera's rays %.4f\n",
              vertical, corrected);
  EXPECT_LT(corrected, kParallaxCorrectedTolerance);
  EXPECT_GT(vertical, kParallaxUncorrectedAtLeast);

  IntegrationOptions bad;
  bad.parallax.enabled = true;
  bad.parallax.camera_z_mm = -1.0;  // below the plane
  EXPECT_FALSE(bad.Check());
}

class IntegrateNormalsSized : public ::testing::TestWithParam<int> {};

// 64: single scale; 128: the robust integrator starts from the 64 x 64 level (multiscale).
INSTANTIATE_TEST_SUITE_P(Sizes, IntegrateNormalsSized, ::testing::Values(64, 128));

TEST_P(IntegrateNormalsSized, HandlesANonRectangularRegion) {
  // A disc of valid pixels; outside it the normals are garbage that must not leak in.
  const Surface s = Sinusoid();
  const int w = GetParam(), h = GetParam();
  const double scale = GetParam() / 64.0;
  Image n = NormalsOf(s, w, h);
  Image mask(w, h, 1, 0.0f, kPitchMm);
  for (int r = 0; r < h; ++r)
    for (int c = 0; c < w; ++c) {
      if (std::hypot(c - 30.0 * scale, r - 34.0 * scale) < 26.0 * scale) {
        mask.at(0, r, c) = 1.0f;
      } else {
        n.at(0, r, c) = 0.9f, n.at(1, r, c) = -0.3f, n.at(2, r, c) = 0.1f;
      }
    }
  n.at(0, 0, 0) = std::nanf("");  // non-finite input outside the mask is ignored too
  for (Integrator method : {Integrator::kDct, Integrator::kRobust}) {
    IntegrationOptions options;
    options.method = method;
    const IntegrationResult result = IntegrateNormals(n, mask, options);
    EXPECT_TRUE(AllFinite(result.height_mm));
    EXPECT_LT(RmsErrorMm(result.height_mm, s, mask) / 0.4, kSinusoidRelativeTolerance) << IntegratorName(method);
    EXPECT_EQ(result.edge_confidence.at(0, 0, 0), 0.0f);
  }
}

// A "tear": z = k * atan2 around a centre near the left border, cut along the ray to the left.
// The gradient field is smooth but not integrable (its curl is 2 pi k); the true surface jumps
// by 2 pi k across the cut. Least squares spreads the jump over the map; the robust integrator
// must keep it on the cut.
TEST_P(IntegrateNormalsSized, RobustKeepsAStepThatDctSmears) {
  const int w = GetParam(), h = GetParam();
  const double xc = 12.0 * kPitchMm, yc = -0.5 * h * kPitchMm;  // on a pixel corner, never a centre
  const double k = 0.05;                                      // jump 2 pi k = 0.31 mm
  Surface s{[=](double x, double y) { return k * std::atan2(y - yc, x - xc); },
            [=](double x, double y) { return -k * (y - yc) / ((x - xc) * (x - xc) + (y - yc) * (y - yc)); },
            [=](double x, double y) { return k * (x - xc) / ((x - xc) * (x - xc) + (y - yc) * (y - yc)); }};
  const Image n = NormalsOf(s, w, h);
  IntegrationOptions options;
  options.method = Integrator::kDct;
  const double dct_rms = RmsErrorMm(IntegrateNormals(n, Image(), options).height_mm, s);
  options.method = Integrator::kRobust;
  const IntegrationResult robust = IntegrateNormals(n, Image(), options);
  const double robust_rms = RmsErrorMm(robust.height_mm, s);
  std::printf("tear %dx%d: RMS height error dct %.4f mm, robust %.4f mm (%d rounds, %d CG iterations)\n", w, h,
              dct_rms, robust_rms, robust.robust_iterations, robust.cg_iterations);
  // Named bars: the robust error is a small fraction of the jump, and of the DCT error.
  constexpr double kRobustBetterFactor = 4.0;
  constexpr double kRobustFractionOfJump = 0.05;
  EXPECT_LT(robust_rms * kRobustBetterFactor, dct_rms) << "robust " << robust_rms << " dct " << dct_rms;
  EXPECT_LT(robust_rms, kRobustFractionOfJump * 2 * std::numbers::pi * k);
  // The jump across the cut (row just above vs just below the centre, far left) is kept.
  const double jump = robust.height_mm.at(0, h / 2 - 1, 2) - robust.height_mm.at(0, h / 2, 2);
  EXPECT_NEAR(std::fabs(jump), 2 * std::numbers::pi * k, 0.2 * 2 * std::numbers::pi * k);
}

// Heights of the least-squares system IntegrateNormals solves (docs/reconstruction.md), from a
// direct sparse Cholesky factorisation: pixel weights from the mask, edge weight = the smaller of
// its pixels' (floored at min_edge_weight), trapezoid targets on edges with both pixels valid.
// z_0 is pinned to remove the constant; the result is anchored at mean 0 over the valid pixels.
std::vector<double> DirectHeights(const Image& normal, const Image& mask) {
  const int w = normal.width(), h = normal.height();
  const int n = w * h;
  const IntegrationOptions defaults;
  std::vector<double> sx(n), sy(n), pw(n);
  for (int r = 0; r < h; ++r)
    for (int c = 0; c < w; ++c) {
      const int i = r * w + c;
      const double nz = normal.at(2, r, c);
      sx[i] = -normal.at(0, r, c) / nz;
      sy[i] = -normal.at(1, r, c) / nz;
      pw[i] = mask.empty() ? 1.0 : mask.at(0, r, c);
    }
  std::vector<Eigen::Triplet<double>> triplets;
  Eigen::VectorXd b = Eigen::VectorXd::Zero(n);
  auto add_edge = [&](int i, int j, double t) {  // energy w (z_j - z_i - t)^2
    const double base = std::min(pw[i], pw[j]);
    const double wt = std::max(base, defaults.min_edge_weight);
    if (!(base > 0.0)) t = 0.0;
    triplets.emplace_back(i, i, wt);
    triplets.emplace_back(j, j, wt);
    triplets.emplace_back(i, j, -wt);
    triplets.emplace_back(j, i, -wt);
    b[j] += wt * t;
    b[i] -= wt * t;
  };
  for (int r = 0; r < h; ++r)
    for (int c = 0; c < w; ++c) {
      const int i = r * w + c;
      if (c + 1 < w) add_edge(i, i + 1, 0.5 * kPitchMm * (sx[i] + sx[i + 1]));
      if (r + 1 < h) add_edge(i, i + w, -0.5 * kPitchMm * (sy[i] + sy[i + w]));
    }
  Eigen::SparseMatrix<double> a(n, n);
  a.setFromTriplets(triplets.begin(), triplets.end());
  // Pin z_0 = 0: drop row and column 0.
  const Eigen::SparseMatrix<double> reduced = a.bottomRightCorner(n - 1, n - 1);
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver(reduced);
  EXPECT_EQ(solver.info(), Eigen::Success);
  const Eigen::VectorXd tail = solver.solve(b.tail(n - 1));
  std::vector<double> z(n, 0.0);
  for (int i = 1; i < n; ++i) z[i] = tail[i - 1];
  double sum = 0.0, count = 0.0;
  for (int i = 0; i < n; ++i)
    if (pw[i] > 0.0) sum += z[i], count += 1.0;
  for (double& v : z) v -= sum / count;
  return z;
}

// Max |height - direct| over the valid pixels (mask > 0; all if empty), relative to the direct
// heights' range there. Holes are a membrane held by min_edge_weight edges, determined only
// loosely by the CG stop; they carry edge_confidence 0 and are not compared.
double RelativeMaxDifference(const Image& height, const std::vector<double>& direct, const Image& mask = Image()) {
  double lo = direct[0], hi = direct[0], worst = 0.0;
  for (std::size_t i = 0; i < direct.size(); ++i) {
    if (!mask.empty() && !(mask.data()[i] > 0.0f)) continue;
    lo = std::min(lo, direct[i]), hi = std::max(hi, direct[i]);
    worst = std::max(worst, std::fabs(height.data()[i] - direct[i]));
  }
  return worst / (hi - lo);
}

// Map sizes whose line lengths have large prime factors (Bluestein for the exact solve, padded
// preconditioner for PCG): 307 x 211 (both prime), 2 x 3 x 5 x 23 = 690 by 3 x 67 = 201.
class IntegrateNormalsAwkward : public ::testing::TestWithParam<std::pair<int, int>> {};
INSTANTIATE_TEST_SUITE_P(Sizes, IntegrateNormalsAwkward,
                         ::testing::Values(std::pair{307, 211}, std::pair{690, 201}));

TEST_P(IntegrateNormalsAwkward, WeightedHeightsMatchTheDirectSolve) {
  const auto [w, h] = GetParam();
  const Surface s = Sinusoid();
  const Image n = NormalsOf(s, w, h);
  // Confidence-like weights: 1, a band of 0.3, a hole of 0 with garbage normals, a ragged right edge.
  Image mask(w, h, 1, 1.0f, kPitchMm);
  Image garbled = n;
  for (int r = 0; r < h; ++r)
    for (int c = 0; c < w; ++c) {
      if (c > w / 3 && c < w / 3 + 12) mask.at(0, r, c) = 0.3f;
      if (std::hypot(c - 0.7 * w, r - 0.5 * h) < 0.15 * h || c > w - 1 - (r % 7)) {
        mask.at(0, r, c) = 0.0f;
        garbled.at(0, r, c) = 0.6f, garbled.at(1, r, c) = 0.3f, garbled.at(2, r, c) = 0.74f;
      }
    }
  const IntegrationResult result = IntegrateNormals(garbled, mask, IntegrationOptions());
  const double difference = RelativeMaxDifference(result.height_mm, DirectHeights(garbled, mask), mask);
  std::printf("%d x %d weighted: %d CG iterations, max |PCG - direct| %.2e of the range\n", w, h,
              result.cg_iterations, difference);
  EXPECT_LT(difference, kDirectSolveRelativeTolerance);
  EXPECT_LE(result.cg_iterations, kMaxWeightedCgIterations);
  EXPECT_GT(result.cg_iterations, 0);  // the weighted path really ran
}

TEST_P(IntegrateNormalsAwkward, ExactDctMatchesTheDirectSolve) {
  const auto [w, h] = GetParam();
  const Image n = NormalsOf(Sinusoid(), w, h);
  const IntegrationResult result = IntegrateNormals(n, Image(), IntegrationOptions());
  const double difference = RelativeMaxDifference(result.height_mm, DirectHeights(n, Image()));
  std::printf("%d x %d unweighted: max |DCT - direct| %.2e of the range\n", w, h, difference);
  EXPECT_EQ(result.cg_iterations, 0);
  EXPECT_LT(difference, kExactDirectRelativeTolerance);
}

TEST(IntegrateNormals, TinyAndDegenerateMapsStayFinite) {
  for (auto [w, h] : {std::pair{1, 1}, std::pair{3, 2}, std::pair{2, 3}, std::pair{1, 7}}) {
    Image n(w, h, 3, 0.0f, kPitchMm);
    for (int r = 0; r < h; ++r)
      for (int c = 0; c < w; ++c) n.at(2, r, c) = 1.0f;
    n.at(0, 0, 0) = 1.0f, n.at(2, 0, 0) = 0.0f;  // a horizontal normal: clamped, not infinite
    for (Integrator method : {Integrator::kDct, Integrator::kRobust}) {
      IntegrationOptions options;
      options.method = method;
      const IntegrationResult result = IntegrateNormals(n, Image(), options);
      EXPECT_TRUE(AllFinite(result.height_mm)) << w << "x" << h;
    }
  }
  Image zeros(4, 4, 3, 0.0f, kPitchMm);  // no valid normal at all
  const IntegrationResult result = IntegrateNormals(zeros, Image(), IntegrationOptions());
  EXPECT_TRUE(AllFinite(result.height_mm));
}

TEST(IntegrateNormals, RejectsBadArguments) {
  Image n(4, 4, 3, 0.0f, 0.0);  // no pitch
  EXPECT_THROW(IntegrateNormals(n, Image(), IntegrationOptions()), std::invalid_argument);
  n.set_pitch_mm(kPitchMm);
  EXPECT_THROW(IntegrateNormals(n, Image(3, 4, 1), IntegrationOptions()), std::invalid_argument);
  IntegrationOptions bad;
  bad.min_normal_z = 0.0;
  EXPECT_THROW(IntegrateNormals(n, Image(), bad), std::invalid_argument);
  EXPECT_THROW(ParseIntegrator("fft"), std::invalid_argument);
}

}  // namespace
}  // namespace u3mscan::reconstruction
