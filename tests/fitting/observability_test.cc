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

TEST(Observability, UniformWithinNoise) {
  ObservabilityOptions options;
  EXPECT_TRUE(IsUniformWithinNoise(0.005, 0.0, options));    // below the absolute tolerance
  EXPECT_TRUE(IsUniformWithinNoise(0.03, 0.02, options));    // within 2 sigma
  EXPECT_FALSE(IsUniformWithinNoise(0.1, 0.02, options));
}

}  // namespace
}  // namespace u3mscan::fitting
