#include "fitting/observability.h"

#include <gtest/gtest.h>

#include <cmath>

namespace u3mscan::fitting {
namespace {

using Matrix7 = Eigen::Matrix<double, kFitParameterCount, kFitParameterCount>;
constexpr double kStdTolerance = 1e-9;

ParameterMask All() {
  ParameterMask m;
  m.fill(true);
  return m;
}

TEST(Observability, ParameterWithoutInformationIsLeftOutWithReason) {
  Matrix7 fisher = Matrix7::Identity() * 1e6;
  const int sheen = static_cast<int>(FitParameter::kSheen);
  fisher(sheen, sheen) = 0.0;
  ObservabilityContext context;
  context.pixel_count = 1;
  context.residual_count = 100;
  const ObservabilityDecision d = DecideObservability(fisher, All(), context, ObservabilityOptions());
  EXPECT_FALSE(d.measured[sheen]);
  EXPECT_TRUE(std::isinf(d.std_dev[sheen]));
  EXPECT_NE(d.reason[sheen].find("oblique"), std::string::npos) << d.reason[sheen];
  for (int i = 0; i < kFitParameterCount; ++i) {
    if (i == sheen) continue;
    EXPECT_TRUE(d.measured[i]) << FitParameterName(i);
    EXPECT_NEAR(d.std_dev[i], 1e-3, kStdTolerance);
  }
}

TEST(Observability, ExactTradeOffIsDetected) {
  // Two parameters that act only through their sum are together unconstrained: the rule leaves
  // one out, after which the other is well determined.
  Matrix7 fisher = Matrix7::Identity() * 1e6;
  const int s = static_cast<int>(FitParameter::kSpecular), t = static_cast<int>(FitParameter::kSpecularTint);
  fisher(s, s) = fisher(t, t) = fisher(s, t) = fisher(t, s) = 1e6;
  ObservabilityContext context;
  context.pixel_count = 1;
  context.residual_count = 100;
  const ObservabilityDecision d = DecideObservability(fisher, All(), context, ObservabilityOptions());
  EXPECT_NE(d.measured[s], d.measured[t]);
}

TEST(Observability, SystematicFloorCapsManyPixels) {
  // Weak information per pixel: 10^4 pixels would pin it statistically, 16 effective ones do not.
  Matrix7 fisher = Matrix7::Identity() * 1e6;
  const int sheen = static_cast<int>(FitParameter::kSheen);
  fisher(sheen, sheen) = 1e4 * 10.0;  // 10 per pixel: std 0.32 for one pixel
  ObservabilityContext context;
  context.pixel_count = 10000;
  context.residual_count = 1000000;
  ObservabilityOptions options;
  EXPECT_FALSE(DecideObservability(fisher, All(), context, options).measured[sheen]);
  options.effective_pixels = 10000;
  EXPECT_TRUE(DecideObservability(fisher, All(), context, options).measured[sheen]);
}

TEST(Observability, PoorFitInflatesUncertainty) {
  Matrix7 fisher = Matrix7::Identity() * 100.0;  // std 0.1 with chi^2 = 1
  ObservabilityContext context;
  context.pixel_count = 1;
  context.residual_count = 101;  // one free parameter: 100 degrees of freedom
  context.cost = 0.5 * 100.0 * 4.0;  // reduced chi^2 = 4
  ParameterMask free{};
  free[0] = true;
  EXPECT_NEAR(PosteriorStdDev(fisher, free, context, ObservabilityOptions())[0], 0.2, 1e-3);
}

TEST(Observability, NonCandidatesAreHeldByOptions) {
  ParameterMask candidates = All();
  const int metallic = static_cast<int>(FitParameter::kMetallic);
  candidates[metallic] = false;
  ObservabilityContext context;
  context.pixel_count = 1;
  context.residual_count = 100;
  const auto d = DecideObservability(Matrix7::Identity() * 1e6, candidates, context, ObservabilityOptions());
  EXPECT_FALSE(d.measured[metallic]);
  EXPECT_NE(d.reason[metallic].find("options"), std::string::npos);
}

TEST(PixelInformation, WithoutNormalColumnsItIsJTransposeJ) {
  Eigen::MatrixXd j(9, kFitParameterCount);
  for (int r = 0; r < j.rows(); ++r) {
    for (int c = 0; c < j.cols(); ++c) j(r, c) = std::sin(1.0 + r * 0.7 + c * 1.3);
  }
  const Matrix7 info = PixelInformation(j, Eigen::MatrixXd());
  EXPECT_LT((info - j.transpose() * j).cwiseAbs().maxCoeff(), kStdTolerance);
}

TEST(PixelInformation, ALobeATiltImitatesCarriesNoInformationAndOneItCannotKeepsAll) {
  // Residual rows of one pixel: specular's column is exactly what a tilt of the normal about x
  // does; roughness's is orthogonal to both tilts. The first loses its information, the second
  // keeps all of it.
  const int rows = 12;
  const int roughness = static_cast<int>(FitParameter::kRoughness);
  const int specular = static_cast<int>(FitParameter::kSpecular);
  Eigen::MatrixXd j = Eigen::MatrixXd::Zero(rows, kFitParameterCount);
  Eigen::MatrixXd tilt(rows, 2);
  for (int r = 0; r < rows; ++r) {
    tilt(r, 0) = r % 2 == 0 ? 1.0 : -1.0;        // alternating
    tilt(r, 1) = r < rows / 2 ? 1.0 : -1.0;       // first half against second
    j(r, specular) = 0.3 * tilt(r, 0);
    j(r, roughness) = (r % 4 < 2 ? 1.0 : -1.0) * (r < rows / 2 ? 1.0 : -1.0);  // orthogonal to both
  }
  ASSERT_NEAR(j.col(roughness).dot(tilt.col(0)), 0.0, kStdTolerance);
  ASSERT_NEAR(j.col(roughness).dot(tilt.col(1)), 0.0, kStdTolerance);
  const Matrix7 info = PixelInformation(j, tilt);
  EXPECT_NEAR(info(specular, specular), 0.0, kStdTolerance);
  EXPECT_NEAR(info(roughness, roughness), j.col(roughness).squaredNorm(), kStdTolerance);
  // Through the posterior: with the tilts marginalised specular is unconstrained.
  ParameterMask free{};
  free[roughness] = free[specular] = true;
  ObservabilityContext context;
  context.pixel_count = 1;
  context.residual_count = rows;
  const ParameterVector exact = PosteriorStdDev(j.transpose() * j, free, context, ObservabilityOptions());
  const ParameterVector marginal = PosteriorStdDev(info, free, context, ObservabilityOptions());
  EXPECT_TRUE(std::isfinite(exact[specular]));
  EXPECT_TRUE(std::isinf(marginal[specular]));
  EXPECT_NEAR(marginal[roughness], exact[roughness], kStdTolerance);
}

TEST(PixelInformation, APartialTradeOffRaisesTheStdAndATiltWithoutInformationTakesNothing) {
  const int rows = 8;
  const int specular = static_cast<int>(FitParameter::kSpecular);
  Eigen::MatrixXd j = Eigen::MatrixXd::Zero(rows, kFitParameterCount);
  Eigen::MatrixXd tilt = Eigen::MatrixXd::Zero(rows, 2);  // the y tilt has no effect at all
  for (int r = 0; r < rows; ++r) {
    tilt(r, 0) = std::cos(0.9 * r);
    j(r, specular) = std::cos(0.9 * r) + 0.5 * std::sin(1.7 * r + 0.3);
  }
  const Matrix7 info = PixelInformation(j, tilt);
  ASSERT_TRUE(info.allFinite());
  // Schur complement: what is left of specular's column after its projection on the x tilt.
  const Eigen::VectorXd t = tilt.col(0);
  const Eigen::VectorXd residual = j.col(specular) - t * (t.dot(j.col(specular)) / t.squaredNorm());
  EXPECT_NEAR(info(specular, specular), residual.squaredNorm(), 1e-9 * j.col(specular).squaredNorm());
  EXPECT_LT(info(specular, specular), j.col(specular).squaredNorm());
  EXPECT_GT(info(specular, specular), 0.0);
}

TEST(Observability, UniformWithinNoise) {
  ObservabilityOptions options;
  EXPECT_TRUE(IsUniformWithinNoise(0.005, 0.0, options));    // below the absolute tolerance
  EXPECT_TRUE(IsUniformWithinNoise(0.03, 0.02, options));    // within 2 sigma
  EXPECT_FALSE(IsUniformWithinNoise(0.1, 0.02, options));
}

}  // namespace
}  // namespace u3mscan::fitting
