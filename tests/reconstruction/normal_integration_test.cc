#include "reconstruction/normal_integration.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <functional>
#include <numbers>
#include <random>
#include <vector>

namespace u3mscan::reconstruction {
namespace {

constexpr double kPitchMm = 0.1;
// Round trip of the DCT in double precision.
constexpr double kDctRoundTripTolerance = 1e-12;
// A paraboloid has linear slopes, so the trapezoid edge targets are exact: only round-off remains.
constexpr double kParaboloidToleranceMm = 1e-6;
// A sinusoid of wavelength 32 px: the discretisation error of the edge targets, relative to the
// height range (peak to peak).
constexpr double kSinusoidRelativeTolerance = 0.01;

struct Surface {
  std::function<double(double, double)> z;   // mm at (x, y) mm
  std::function<double(double, double)> dzdx;
  std::function<double(double, double)> dzdy;
};

double PixelX(int c) { return (c + 0.5) * kPitchMm; }
double PixelY(int r) { return -(r + 0.5) * kPitchMm; }  // rows grow with -y

Image NormalsOf(const Surface& s, int w, int h) {
  Image n(w, h, 3, 0.0f, kPitchMm);
  for (int r = 0; r < h; ++r)
    for (int c = 0; c < w; ++c) {
      const double gx = s.dzdx(PixelX(c), PixelY(r)), gy = s.dzdy(PixelX(c), PixelY(r));
      const double len = std::sqrt(gx * gx + gy * gy + 1.0);
      n.at(0, r, c) = static_cast<float>(-gx / len);
      n.at(1, r, c) = static_cast<float>(-gy / len);
      n.at(2, r, c) = static_cast<float>(1.0 / len);
    }
  return n;
}

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
