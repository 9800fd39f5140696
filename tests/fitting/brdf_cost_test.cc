#include "fitting/brdf_cost.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <cmath>
#include <random>
#include <vector>

#include "core/principled_brdf.h"

namespace u3mscan::fitting {
namespace {

// Central differences of the double residuals: truncation O(h^2) ~ 1e-8 relative, rounding
// ~1e-16 / h; the autodiff Jacobian must agree to well within that.
constexpr double kFiniteDifferenceStep = 1e-5;
constexpr double kGradientTolerance = 1e-5;   // relative to the column's largest entry
// Closed-form colour of noise-free data: exact up to rounding and the fixed-point convergence.
constexpr double kColorTolerance = 1e-9;
constexpr int kManyLuminancePasses = 12;
constexpr double kRoundingTolerance = 1e-12;

Eigen::Vector3d Direction(double theta_deg, double phi_deg) {
  const double t = theta_deg * M_PI / 180.0, p = phi_deg * M_PI / 180.0;
  return {std::sin(t) * std::cos(p), std::sin(t) * std::sin(p), std::cos(t)};
}

ParameterVector Params(double roughness, double specular, double specular_tint, double sheen, double sheen_tint,
                       double anisotropic, double metallic) {
  return {roughness, specular, specular_tint, sheen, sheen_tint, anisotropic, metallic};
}

// Observations of one pixel rendered with the core BRDF (directions spread over the hemisphere,
// views overhead and oblique), optionally perturbed.
std::vector<LocalObservation> Render(const ParameterVector& p, const Eigen::Vector3d& color, double perturbation,
                                     std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  PrincipledParams<double> params;
  params.base_color = color;
  params.roughness = p[0];
  params.specular = p[1];
  params.specular_tint = p[2];
  params.sheen = p[3];
  params.sheen_tint = p[4];
  params.anisotropic = p[5];
  params.metallic = p[6];
  std::vector<LocalObservation> out;
  const Eigen::Vector3d views[] = {Direction(3, 10), Direction(60, 0)};
  for (const Eigen::Vector3d& v : views) {
    for (int i = 0; i < 12; ++i) {
      LocalObservation o;
      o.light_local = Direction(10.0 + 6.5 * i, 180.0 + 37.0 * i);
      o.view_local = v;
      o.irradiance = 1.0 + 0.1 * i;
      const Vec3<double> f = EvaluatePrincipled(params, Vec3<double>(o.light_local), Vec3<double>(v));
      o.rgb = f * o.light_local.z() * o.irradiance;
      for (int c = 0; c < 3; ++c) o.rgb(c) *= 1.0 + perturbation * u(rng);
      o.weight = Eigen::Vector3d::Constant(100.0);
      out.push_back(o);
    }
  }
  return out;
}

TEST(BrdfCost, AutodiffJacobianMatchesFiniteDifferences) {
  // Interior point with every lobe active, tints in play, and a Huber loss active on perturbed data.
  const ParameterVector p = Params(0.4, 0.6, 0.3, 0.5, 0.4, 0.3, 0.1);
  const auto obs = Render(Params(0.3, 0.5, 0.2, 0.7, 0.5, 0.2, 0.0), {0.6, 0.3, 0.2}, 0.2, 7);
  for (RobustLossKind kind : {RobustLossKind::kNone, RobustLossKind::kHuber, RobustLossKind::kCauchy}) {
    PixelCostSettings settings;
    settings.loss.kind = kind;
    settings.loss.scale = 1.0;
    settings.luminance_start = 0.3;
    settings.luminance_passes = 3;
    Eigen::VectorXd r;
    Eigen::MatrixXd j;
    ASSERT_TRUE(EvaluatePixelJacobian(p, obs, settings, &r, &j));
    std::vector<double> plus(r.size()), minus(r.size()), value(r.size());
    PixelResiduals(p, obs, settings, value.data());
    for (int i = 0; i < r.size(); ++i) EXPECT_NEAR(value[i], r(i), kRoundingTolerance * (1.0 + std::abs(r(i))));
    for (int k = 0; k < kFitParameterCount; ++k) {
      ParameterVector a = p, b = p;
      a[k] += kFiniteDifferenceStep;
      b[k] -= kFiniteDifferenceStep;
      PixelResiduals(a, obs, settings, plus.data());
      PixelResiduals(b, obs, settings, minus.data());
      const double scale = std::max(1.0, j.col(k).cwiseAbs().maxCoeff());
      for (int i = 0; i < r.size(); ++i) {
        const double numeric = (plus[i] - minus[i]) / (2.0 * kFiniteDifferenceStep);
        ASSERT_NEAR(j(i, k), numeric, kGradientTolerance * scale)
            << FitParameterName(k) << " residual " << i << " loss " << static_cast<int>(kind);
      }
    }
  }
}

// Tilt of the normal in NormalTiltJacobianPredictsTheTiltedNormal: small enough for the linear
// prediction, large enough that the untilted residuals are far above its O(tilt^2) error.
constexpr double kTiltRad = 0.01;
constexpr double kLinearPredictionShare = 0.05;  // of the untilted residual norm

TEST(BrdfCost, NormalTiltJacobianPredictsTheTiltedNormal) {
  // Data rendered with the normal tilted by kTiltRad about local x (then about y), fitted with the
  // untilted normal: r(0) + J_tilt * tilt must explain the data (the residuals nearly vanish), which
  // checks both the sign convention and the size of the tilt Jacobian.
  const ParameterVector p = Params(0.5, 0.5, 0.0, 0.3, 0.0, 0.0, 0.0);
  const Eigen::Vector3d color(0.5, 0.35, 0.2);
  const auto flat = Render(p, color, 0.0, 3);
  PixelCostSettings settings;
  settings.loss.kind = RobustLossKind::kNone;
  Eigen::MatrixXd j_tilt;
  std::vector<LocalObservation> scratch;
  ASSERT_TRUE(EvaluateNormalTiltJacobian(p, flat, settings, scratch, &j_tilt));
  ASSERT_EQ(j_tilt.rows(), static_cast<int>(3 * flat.size()));
  ASSERT_EQ(j_tilt.cols(), 2);
  for (int axis = 0; axis < 2; ++axis) {
    // The tilted normal n' = R(tilt) z; in the untilted local frame the data are those of the
    // surface with normal n', i.e. the flat surface's data seen in directions turned by -tilt.
    const Eigen::Vector3d axis_vector = axis == 0 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
    const Eigen::Matrix3d to_tilted_frame = Eigen::AngleAxisd(-kTiltRad, axis_vector).toRotationMatrix();
    std::vector<LocalObservation> data = flat;
    PrincipledParams<double> params;
    params.base_color = color;
    params.roughness = p[0];
    params.specular = p[1];
    params.sheen = p[3];
    for (LocalObservation& o : data) {
      const Vec3<double> l(to_tilted_frame * o.light_local);
      const Vec3<double> v(to_tilted_frame * o.view_local);
      o.rgb = EvaluatePrincipled(params, l, v) * (std::max(0.0, l.z()) * o.irradiance);
    }
    std::vector<double> r0(3 * data.size());
    PixelResiduals(p, data, settings, r0.data());
    const Eigen::Map<const Eigen::VectorXd> untilted(r0.data(), static_cast<Eigen::Index>(r0.size()));
    const Eigen::VectorXd predicted = untilted + j_tilt.col(axis) * kTiltRad;
    ASSERT_GT(untilted.norm(), 0.0);
    EXPECT_LT(predicted.norm(), kLinearPredictionShare * untilted.norm()) << "axis " << axis;
  }
}

TEST(BrdfCost, ClosedFormBaseColorIsExactOnNoiseFreeData) {
  const Eigen::Vector3d color(0.55, 0.25, 0.1);
  // Untinted: one pass is exact. Tinted: the fixed point converges to the exact colour.
  for (const ParameterVector& p : {Params(0.3, 0.5, 0.0, 0.4, 0.0, 0.0, 0.0), Params(0.3, 0.8, 0.7, 0.6, 0.9, 0.2, 0.0)}) {
    const auto obs = Render(p, color, 0.0, 1);
    PixelCostSettings settings;
    settings.luminance_start = 0.9;  // deliberately far from the true 0.33
    ParameterMask free{};
    settings.luminance_passes = LuminancePassesFor(p, free, kManyLuminancePasses);
    const Eigen::Vector3d solved = SolveBaseColor(p, obs, settings);
    EXPECT_NEAR(solved(0), color(0), kColorTolerance);
    EXPECT_NEAR(solved(1), color(1), kColorTolerance);
    EXPECT_NEAR(solved(2), color(2), kColorTolerance);
    std::vector<double> r(3 * obs.size());
    EXPECT_LT(PixelResiduals(p, obs, settings, r.data()), kColorTolerance);
  }
}

TEST(BrdfCost, RobustResidualCarriesTheLoss) {
  // |r'|^2 must equal rho(|r|^2): compare the robust and plain residuals observation by observation.
  const ParameterVector p = Params(0.3, 0.5, 0.0, 0.0, 0.0, 0.0, 0.0);
  const auto obs = Render(Params(0.5, 0.9, 0.0, 0.0, 0.0, 0.0, 0.0), {0.5, 0.5, 0.5}, 0.3, 3);
  PixelCostSettings plain, huber, cauchy;
  plain.loss.kind = RobustLossKind::kNone;
  huber.loss = {RobustLossKind::kHuber, 2.0};
  cauchy.loss = {RobustLossKind::kCauchy, 2.0};
  std::vector<double> r0(3 * obs.size()), r1(r0.size()), r2(r0.size());
  PixelResiduals(p, obs, plain, r0.data());
  PixelResiduals(p, obs, huber, r1.data());
  PixelResiduals(p, obs, cauchy, r2.data());
  int outliers = 0;
  for (std::size_t i = 0; i < obs.size(); ++i) {
    double s = 0, s1 = 0, s2 = 0;
    for (int c = 0; c < 3; ++c) {
      s += r0[3 * i + c] * r0[3 * i + c];
      s1 += r1[3 * i + c] * r1[3 * i + c];
      s2 += r2[3 * i + c] * r2[3 * i + c];
    }
    const double a = 2.0;
    const double huber_rho = s <= a * a ? s : 2.0 * a * std::sqrt(s) - a * a;
    EXPECT_NEAR(s1, huber_rho, 1e-9 * (1.0 + s));
    EXPECT_NEAR(s2, a * a * std::log1p(s / (a * a)), 1e-9 * (1.0 + s));
    if (s > a * a) ++outliers;
  }
  EXPECT_GT(outliers, 0) << "the test data must exercise the robust branch";
}

// Observations a hair from the data (noise-free renders, 1e-9 relative): the Cauchy loss is then
// the square itself, |r'| = |r|, with a finite Jacobian. log(1 + s / a^2) rounds to 0 there, which
// made the residual 0 and its derivative infinite.
constexpr double kHairPerturbation = 1e-9;
constexpr double kTinyResidualFactorTolerance = 1e-6;  // relative: 1 - factor ~ s / (2 a^2)

TEST(BrdfCost, TheCauchyLossOfANearlyExactObservationIsFiniteAndQuadratic) {
  const ParameterVector p = Params(0.9, 0.05, 0.0, 0.0, 0.0, 0.0, 0.0);
  const auto obs = Render(p, {0.002, 0.002, 0.002}, kHairPerturbation, 5);
  PixelCostSettings plain, cauchy;
  plain.loss.kind = RobustLossKind::kNone;
  cauchy.loss = {RobustLossKind::kCauchy, 2.0};
  Eigen::VectorXd r0, r2;
  Eigen::MatrixXd j0, j2;
  ASSERT_TRUE(EvaluatePixelJacobian(p, obs, plain, &r0, &j0));
  ASSERT_TRUE(EvaluatePixelJacobian(p, obs, cauchy, &r2, &j2));
  int in_the_rounding_band = 0;
  for (std::size_t i = 0; i < obs.size(); ++i) {
    const double s = r0.segment<3>(3 * i).squaredNorm();
    // The band where 1 + s / a^2 == 1 in double precision.
    if (s > 0.0 && 1.0 + s / 4.0 == 1.0) ++in_the_rounding_band;
    for (int c = 0; c < 3; ++c) {
      const int row = static_cast<int>(3 * i) + c;
      EXPECT_NEAR(r2(row), r0(row), kTinyResidualFactorTolerance * std::abs(r0(row))) << "observation " << i;
      EXPECT_TRUE(j2.row(row).allFinite()) << "observation " << i << ": " << j2.row(row);
    }
  }
  EXPECT_GT(in_the_rounding_band, 0) << "the data must reach the band where log(1 + s / a^2) rounds to 0";
}

// Each observation of `plain` (made by Render) as a facet run of three facets tilted about the
// local x axis by the given angles (a tilted facet sees every direction turned back), its data the
// weighted sum of the facets' renders with `p` and `color`.
std::vector<LocalObservation> AsFacetRuns(const std::vector<LocalObservation>& plain, const ParameterVector& p,
                                          const Eigen::Vector3d& color) {
  const double tilts_deg[] = {-15.0, 5.0, 20.0};
  const double shares[] = {0.2, 0.5, 0.3};
  std::vector<LocalObservation> runs;
  for (const LocalObservation& o : plain) {
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    for (int f = 0; f < 3; ++f) {
      const Eigen::Matrix3d back = Eigen::AngleAxisd(-tilts_deg[f] * M_PI / 180.0, Eigen::Vector3d::UnitX()).toRotationMatrix();
      LocalObservation e = o;
      e.light_local = back * o.light_local;
      e.view_local = back * o.view_local;
      e.facet_weight = shares[f];
      e.continues = f < 2;
      sum += shares[f] * RenderLocal(p, color, e.light_local, e.view_local, e.irradiance);
      if (e.continues) {
        e.rgb.setZero();
        e.weight.setZero();
      }
      runs.push_back(e);
    }
    runs.back().rgb = sum;
  }
  return runs;
}

TEST(BrdfCost, AFacetRunIsPredictedAsTheWeightedSumOfItsFacets) {
  const Eigen::Vector3d color(0.4, 0.3, 0.2);
  const ParameterVector p = Params(0.45, 0.6, 0.0, 0.7, 0.0, 0.0, 0.0);
  const std::vector<LocalObservation> plain = Render(p, color, 0.0, 3);
  const std::vector<LocalObservation> runs = AsFacetRuns(plain, p, color);
  EXPECT_EQ(CountMeasurements(runs), static_cast<int>(plain.size()));
  EXPECT_EQ(CountMeasurements(plain), static_cast<int>(plain.size()));
  PixelCostSettings settings;
  const Eigen::Vector3d solved = SolveBaseColor(p, runs, settings);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(solved(c), color(c), kColorTolerance);
  std::vector<double> r(3 * runs.size());
  EXPECT_LT(PixelResiduals(p, runs, settings, r.data()), kColorTolerance);
  for (std::size_t i = 0; i < runs.size(); ++i) {
    if (!runs[i].continues) continue;
    for (int c = 0; c < 3; ++c) EXPECT_EQ(r[3 * i + c], 0.0) << "a continued entry has no residual of its own";
  }
  // The run as one rendered value, and the same data read as one facet (the untilted normal): the
  // facets' mixture is not the plain observation.
  std::size_t end = 0;
  EXPECT_LT((RenderRun(p, color, runs, 0, &end) - runs[2].rgb).norm(), kRoundingTolerance);
  EXPECT_EQ(end, 3u);
  std::vector<LocalObservation> one_normal = plain;
  for (std::size_t i = 0; i < plain.size(); ++i) one_normal[i].rgb = runs[3 * i + 2].rgb;
  std::vector<double> r_one(3 * one_normal.size());
  EXPECT_GT(PixelResiduals(p, one_normal, settings, r_one.data()), 1e3 * kColorTolerance);
  // Its Jacobian has the continued entries' rows at 0 and the run's at the last entry.
  Eigen::VectorXd residuals;
  Eigen::MatrixXd jacobian;
  ASSERT_TRUE(EvaluatePixelJacobian(p, runs, settings, &residuals, &jacobian));
  EXPECT_EQ(jacobian.row(0).norm(), 0.0);
  EXPECT_GT(jacobian.row(6).norm(), 0.0);
}

TEST(BrdfCost, DefaultsAreTheU3mDefaults) {
  EXPECT_EQ(FitParameterDefault(FitParameter::kRoughness), 0.7);
  EXPECT_EQ(FitParameterDefault(FitParameter::kSpecular), 0.5);
  EXPECT_EQ(FitParameterDefault(FitParameter::kSheen), 0.0);
  EXPECT_EQ(FitParameterDefault(FitParameter::kMetallic), 0.0);
  EXPECT_STREQ(FitParameterName(FitParameter::kSheenTint), "sheen_tint");
}

}  // namespace
}  // namespace u3mscan::fitting
