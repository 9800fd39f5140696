#include "core/principled_brdf.h"

#include <ceres/jet.h>
#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace u3mscan {
namespace {

using Vec3d = Vec3<double>;

// Reciprocity and Jet-vs-double agree to rounding; finite differences to their truncation error.
constexpr double kReciprocityTolerance = 1e-10;
constexpr double kJetValueTolerance = 1e-12;
constexpr double kFiniteDifferenceStep = 1e-6;
constexpr double kGradientRelativeTolerance = 1e-4;
// Disney's diffuse is not energy conserving: its retro-reflection (Fd90 = 0.5 + 2 r cos_d^2 in
// [0.5, 2.5]) lets the directional albedo of a white base leave [0, 1] (Burley 2012, section 5.3).
// The known bounds follow from 1 - 0.5 SW <= 1 + (Fd90 - 1) SW <= 1 + 1.5 SW and
// 2 * integral_0^1 SW(mu) mu dmu = 1/21:
//   (1 - 0.5/21) (1 - 0.5 SW(cos_v)) <= albedo <= (1 + 1.5/21) (1 + 1.5 SW(cos_v)).
// Pure GGX specular with a separable Smith G only loses energy: albedo <= 1.
constexpr double kQuadratureTolerance = 2e-3;
constexpr double kSpecularAlbedoBound = 1.0 + kQuadratureTolerance;
constexpr int kQuadratureSteps = 256;

Vec3d Direction(double theta_deg, double phi_deg) {
  const double t = theta_deg * M_PI / 180.0, p = phi_deg * M_PI / 180.0;
  return {std::sin(t) * std::cos(p), std::sin(t) * std::sin(p), std::cos(t)};
}

PrincipledParams<double> RandomParams(std::mt19937& rng) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  PrincipledParams<double> p;
  p.base_color = Vec3d(u(rng), u(rng), u(rng));
  p.metallic = u(rng);
  p.subsurface = u(rng);
  p.specular = u(rng);
  p.roughness = 0.05 + 0.95 * u(rng);
  p.specular_tint = u(rng);
  p.anisotropic = u(rng);
  p.sheen = u(rng);
  p.sheen_tint = u(rng);
  p.clearcoat = u(rng);
  p.clearcoat_gloss = u(rng);
  return p;
}

Vec3d RandomUpperDirection(std::mt19937& rng) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  return Direction(89.0 * u(rng), 360.0 * u(rng));
}

// Directional albedo: integral over the hemisphere of f(L, V) cos_l dL, midpoint rule in
// (cos theta, phi), which is uniform in projected solid angle weight.
Vec3d DirectionalAlbedo(const PrincipledParams<double>& p, const Vec3d& v) {
  Vec3d sum = Vec3d::Zero();
  const int n = kQuadratureSteps;
  for (int i = 0; i < n; ++i) {
    const double mu = (i + 0.5) / n;  // cos theta
    const double s = std::sqrt(1.0 - mu * mu);
    for (int j = 0; j < n; ++j) {
      const double phi = 2.0 * M_PI * (j + 0.5) / n;
      const Vec3d l(s * std::cos(phi), s * std::sin(phi), mu);
      sum += EvaluatePrincipled(p, l, v) * mu;
    }
  }
  return sum * (2.0 * M_PI / (n * n));  // d(omega) = d(mu) d(phi)
}

TEST(PrincipledBrdf, IsReciprocal) {
  std::mt19937 rng(7);
  for (int trial = 0; trial < 500; ++trial) {
    const auto p = RandomParams(rng);
    const Vec3d l = RandomUpperDirection(rng), v = RandomUpperDirection(rng);
    const Vec3d f_lv = EvaluatePrincipled(p, l, v), f_vl = EvaluatePrincipled(p, v, l);
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(f_lv(c), f_vl(c), kReciprocityTolerance * std::max(1.0, std::abs(f_lv(c))));
    }
  }
}

TEST(PrincipledBrdf, IsNonNegativeAndFinite) {
  std::mt19937 rng(11);
  for (int trial = 0; trial < 2000; ++trial) {
    auto p = RandomParams(rng);
    if (trial % 4 == 0) p.roughness = 0.0;  // mirror limit: alpha clamped to 0.001
    const Vec3d f = EvaluatePrincipled(p, RandomUpperDirection(rng), RandomUpperDirection(rng));
    for (int c = 0; c < 3; ++c) {
      ASSERT_TRUE(std::isfinite(f(c)));
      ASSERT_GE(f(c), 0.0);
    }
  }
}

TEST(PrincipledBrdf, ZeroBelowTheHorizon) {
  PrincipledParams<double> p;
  EXPECT_EQ(EvaluatePrincipled(p, Direction(95, 0), Direction(10, 0)), Vec3d::Zero());
  EXPECT_EQ(EvaluatePrincipled(p, Direction(10, 0), Direction(90.5, 0)), Vec3d::Zero());
}

TEST(PrincipledBrdf, LambertianLimitAtNormalIncidence) {
  // Roughness 0.5, L = V = normal: cos_d = 1 so Fd = 1 and the diffuse term is C / pi exactly.
  PrincipledParams<double> p;
  p.base_color = Vec3d(0.5, 0.25, 0.125);
  p.specular = 0.0;
  const Vec3d n(0, 0, 1);
  const Vec3d f = EvaluatePrincipled(p, n, n);
  // Specular 0 still leaves Schlick's SW(1) = 0 Fresnel: F = 0, so only diffuse remains.
  EXPECT_NEAR(f(0), 0.5 / M_PI, 1e-12);
  EXPECT_NEAR(f(1), 0.25 / M_PI, 1e-12);
  EXPECT_NEAR(f(2), 0.125 / M_PI, 1e-12);
}

TEST(PrincipledBrdf, WhiteFurnaceWithinKnownBounds) {
  for (double roughness : {0.05, 0.3, 0.6, 1.0}) {
    for (double theta_v : {0.0, 30.0, 60.0, 80.0}) {
      const Vec3d v = Direction(theta_v, 0.0);
      PrincipledParams<double> diffuse;
      diffuse.base_color = Vec3d::Ones();
      diffuse.specular = 0.0;
      diffuse.roughness = roughness;
      const double a_diffuse = DirectionalAlbedo(diffuse, v)(0);
      const double sw_v = brdf::SchlickWeight(v.z());
      EXPECT_LE(a_diffuse, (1.0 + 1.5 / 21.0) * (1.0 + 1.5 * sw_v) + kQuadratureTolerance)
          << "roughness " << roughness << " theta_v " << theta_v;
      EXPECT_GE(a_diffuse, (1.0 - 0.5 / 21.0) * (1.0 - 0.5 * sw_v) - kQuadratureTolerance)
          << "roughness " << roughness << " theta_v " << theta_v;

      PrincipledParams<double> metal;
      metal.base_color = Vec3d::Ones();
      metal.metallic = 1.0;
      metal.roughness = roughness;
      const double a_metal = DirectionalAlbedo(metal, v)(0);
      EXPECT_LE(a_metal, kSpecularAlbedoBound) << "roughness " << roughness << " theta_v " << theta_v;
      // Where the quadrature resolves the lobe and masking is mild, most energy is reflected.
      if (roughness >= 0.3 && roughness <= 0.6 && theta_v <= 60.0) {
        EXPECT_GT(a_metal, 0.7);
      }
    }
  }
}

TEST(PrincipledBrdf, SheenIsInvisibleFromAboveButNotAtGrazing) {
  // docs/principled-brdf.md: camera overhead, light above the horizon -> SW(cos_d) <= 0.002.
  PrincipledParams<double> base;
  base.base_color = Vec3d(0.5, 0.5, 0.5);
  base.specular = 0.0;  // compare sheen with the diffuse it rides on
  base.roughness = 0.9;  // a fabric: a broad specular lobe that does not hide the sheen
  PrincipledParams<double> velvet = base;
  velvet.sheen = 1.0;
  const Vec3d v(0, 0, 1);
  const Vec3d l = Direction(75, 0);
  const double relative = (EvaluatePrincipled(velvet, l, v) - EvaluatePrincipled(base, l, v)).norm() /
                          EvaluatePrincipled(base, l, v).norm();
  EXPECT_LT(relative, 0.01);
  // Oblique view from the opposite side of a grazing light: cos_d small, sheen strong.
  const Vec3d v_oblique = Direction(70, 180);
  const Vec3d l_grazing = Direction(80, 0);
  const double relative_oblique =
      (EvaluatePrincipled(velvet, l_grazing, v_oblique) - EvaluatePrincipled(base, l_grazing, v_oblique)).norm() /
      EvaluatePrincipled(base, l_grazing, v_oblique).norm();
  EXPECT_GT(relative_oblique, 0.1);
}

using Jet = ceres::Jet<double, 11>;

PrincipledParams<Jet> ToJet(const PrincipledParams<double>& p) {
  PrincipledParams<Jet> j;
  const double* values[] = {&p.metallic, &p.subsurface, &p.specular, &p.roughness, &p.specular_tint,
                            &p.anisotropic, &p.sheen, &p.sheen_tint, &p.clearcoat, &p.clearcoat_gloss};
  Jet* jets[] = {&j.metallic, &j.subsurface, &j.specular, &j.roughness, &j.specular_tint,
                 &j.anisotropic, &j.sheen, &j.sheen_tint, &j.clearcoat, &j.clearcoat_gloss};
  for (int i = 0; i < 10; ++i) *jets[i] = Jet(*values[i], i);
  // Base colour: one shared derivative slot (index 10) on all three channels.
  for (int c = 0; c < 3; ++c) j.base_color(c) = Jet(p.base_color(c), 10);
  return j;
}

double* ScalarSlot(PrincipledParams<double>& p, int index) {
  double* slots[] = {&p.metallic, &p.subsurface, &p.specular, &p.roughness, &p.specular_tint,
                     &p.anisotropic, &p.sheen, &p.sheen_tint, &p.clearcoat, &p.clearcoat_gloss};
  return slots[index];
}

TEST(PrincipledBrdf, JetValueEqualsDoubleValueAndGradientMatchesFiniteDifferences) {
  std::mt19937 rng(3);
  for (int trial = 0; trial < 200; ++trial) {
    auto p = RandomParams(rng);
    // Keep away from the clamps and kinks (alpha floor, 0/1 bounds) where one-sided derivatives differ.
    p.roughness = 0.2 + 0.7 * p.roughness;
    for (int i = 0; i < 10; ++i) {
      if (i == 3) continue;
      double* s = ScalarSlot(p, i);
      *s = 0.05 + 0.9 * *s;
    }
    const Vec3d l = RandomUpperDirection(rng), v = RandomUpperDirection(rng);
    const Vec3d f = EvaluatePrincipled(p, l, v);
    const Vec3<Jet> fj = EvaluatePrincipled(ToJet(p), Vec3<Jet>(l.cast<Jet>()), Vec3<Jet>(v.cast<Jet>()));
    for (int c = 0; c < 3; ++c) ASSERT_NEAR(fj(c).a, f(c), kJetValueTolerance * std::max(1.0, f(c)));

    for (int i = 0; i < 10; ++i) {
      auto plus = p, minus = p;
      *ScalarSlot(plus, i) += kFiniteDifferenceStep;
      *ScalarSlot(minus, i) -= kFiniteDifferenceStep;
      const Vec3d fd = (EvaluatePrincipled(plus, l, v) - EvaluatePrincipled(minus, l, v)) / (2 * kFiniteDifferenceStep);
      for (int c = 0; c < 3; ++c) {
        const double scale = std::max({1e-3, std::abs(fd(c)), std::abs(fj(c).v[i])});
        EXPECT_NEAR(fj(c).v[i], fd(c), kGradientRelativeTolerance * scale)
            << "parameter " << i << " channel " << c << " trial " << trial;
      }
    }
    // Base colour: all three channels moved together (slot 10).
    auto plus = p, minus = p;
    plus.base_color.array() += kFiniteDifferenceStep;
    minus.base_color.array() -= kFiniteDifferenceStep;
    const Vec3d fd = (EvaluatePrincipled(plus, l, v) - EvaluatePrincipled(minus, l, v)) / (2 * kFiniteDifferenceStep);
    for (int c = 0; c < 3; ++c) {
      const double scale = std::max({1e-3, std::abs(fd(c)), std::abs(fj(c).v[10])});
      EXPECT_NEAR(fj(c).v[10], fd(c), kGradientRelativeTolerance * scale) << "base colour, trial " << trial;
    }
  }
}

// EvaluatePrincipled leaves out the subsurface and clearcoat lobes when their weights are exactly
// 0 (brdf::IsExactlyZero). Both lobes evaluated with a weight of 0 add exactly nothing (the
// terms below, to the last bit), and a Jet weight whose value is 0 but whose derivative is not is
// still evaluated and differentiated:
// d f / d subsurface = C (ss - fd) / pi and d f / d clearcoat = the clearcoat lobe at weight 1.
TEST(PrincipledBrdf, LobesOfWeightZeroAreLeftOutExactlyButStillDifferentiated) {
  std::mt19937 rng(11);
  for (int trial = 0; trial < 100; ++trial) {
    auto p = RandomParams(rng);
    p.subsurface = 0.0;
    p.clearcoat = 0.0;
    const Vec3d l = RandomUpperDirection(rng), v = RandomUpperDirection(rng);
    const Vec3d f = EvaluatePrincipled(p, l, v);
    // The skipped lobes' terms as the full formula adds them (Mix and the clearcoat sum).
    const Vec3d h = (l + v).normalized();
    const double fd = brdf::DisneyDiffuse(l.z(), v.z(), l.dot(h), p.roughness);
    const double ss = brdf::DisneySubsurface(l.z(), v.z(), l.dot(h), p.roughness);
    EXPECT_EQ(brdf::Mix(fd, ss, p.subsurface), fd) << "trial " << trial;
    EXPECT_EQ(brdf::ClearcoatLobe(p, l.z(), v.z(), h.z(), l.dot(h)), 0.0) << "trial " << trial;

    const Vec3<Jet> fj = EvaluatePrincipled(ToJet(p), Vec3<Jet>(l.cast<Jet>()), Vec3<Jet>(v.cast<Jet>()));
    auto coated = p;
    coated.clearcoat = 1.0;
    const double clearcoat_lobe = brdf::ClearcoatLobe(coated, l.z(), v.z(), h.z(), l.dot(h));
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(fj(c).a, f(c), kJetValueTolerance * std::max(1.0, f(c))) << "trial " << trial;
      const double d_subsurface = p.base_color(c) * (ss - fd) / brdf::kPi * (1.0 - p.metallic);
      EXPECT_NEAR(fj(c).v[1], d_subsurface, kJetValueTolerance) << "subsurface, channel " << c << " trial " << trial;
      EXPECT_NEAR(fj(c).v[8], clearcoat_lobe, kJetValueTolerance * std::max(1.0, clearcoat_lobe))
          << "clearcoat, channel " << c << " trial " << trial;
    }
  }
}

// The colour parts give the whole BRDF for every base colour: C per_colour + TintColor(C) per_tint
// + white, with every lobe on (metallic, subsurface, clearcoat, anisotropy), a black colour (white
// tint) and a pair below the horizon (all 0). To rounding: the same lobes, summed in another order.
constexpr double kColourPartsTolerance = 1e-12;  // relative to the BRDF's largest channel (or 1)
TEST(PrincipledBrdf, ColourPartsGiveTheBrdfOfEveryBaseColour) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int trial = 0; trial < 500; ++trial) {
    PrincipledParams<double> p = RandomParams(rng);
    if (trial % 5 == 0) p.clearcoat = 0.0;
    if (trial % 7 == 0) p.subsurface = 0.0;
    const Vec3d l = RandomUpperDirection(rng), v = RandomUpperDirection(rng);
    const PrincipledColourParts<double> parts = EvaluatePrincipledColourParts(p, l, v);
    for (const Vec3d& colour : {p.base_color, Vec3d(0.0, 0.0, 0.0), Vec3d(1.0, 0.2, 0.05)}) {
      PrincipledParams<double> coloured = p;
      coloured.base_color = colour;
      const Vec3d f = EvaluatePrincipled(coloured, l, v);
      const Vec3d from_parts = colour * parts.per_colour + brdf::TintColor(colour) * parts.per_tint +
                               Vec3d::Constant(parts.white);
      const double scale = std::max(1.0, f.cwiseAbs().maxCoeff());
      EXPECT_NEAR((from_parts - f).cwiseAbs().maxCoeff() / scale, 0.0, kColourPartsTolerance) << trial;
    }
  }
  const PrincipledColourParts<double> below =
      EvaluatePrincipledColourParts(RandomParams(rng), Direction(95.0, 10.0), Direction(30.0, 0.0));
  EXPECT_EQ(below.per_colour, 0.0);
  EXPECT_EQ(below.per_tint, 0.0);
  EXPECT_EQ(below.white, 0.0);
}

TEST(PrincipledBrdf, RunsOnFloat) {
  PrincipledParams<float> p;
  const Vec3<float> l(0.0f, 0.6f, 0.8f), v(0.0f, 0.0f, 1.0f);
  const Vec3<float> f = EvaluatePrincipled(p, l, v);
  PrincipledParams<double> pd;
  const Vec3d fd = EvaluatePrincipled(pd, Vec3d(0.0, 0.6, 0.8), Vec3d(0.0, 0.0, 1.0));
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(f(c), fd(c), 1e-5);
}

}  // namespace
}  // namespace u3mscan
