#include "fitting/principled_fit.h"
#include "fitting/map_rules.h"
#include "fitting/tiled_fit.h"
#include "pipeline/fit_json.h"

#include <gtest/gtest.h>

#include <cstdio>

#include <limits>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <iostream>
#include <map>
#include <mutex>
#include <random>
#include <set>

#include "core/logging.h"
#include "test_scene.h"

namespace u3mscan::fitting {
namespace {

using testing::GrazingLights;
using testing::MakeScene;
using testing::OverheadLights;
using testing::OverheadAndGrazingLights;
using testing::RelativeRmse;
using testing::Scene;
using testing::SceneSpec;

// Noise-free renders with the fitter's own BRDF: recovery is limited by the solver tolerances
// (function/parameter 1e-10) and float32 images, not by the model.
constexpr double kExactParameterTolerance = 2e-3;
constexpr double kExactColorTolerance = 2e-3;
// The issue's acceptance figure for lights left out of the fit.
constexpr double kHeldOutRelativeRmse = 0.02;
// Stiff case: a roughness the data exclude from being large.
constexpr double kStiffRoughnessBound = 0.1;
// Sensor-like noise (relative, Gaussian per channel) and the issue's accuracy targets.
constexpr double kNoiseRelative = 0.01;
constexpr double kHighNoiseRelative = 0.06;
constexpr double kTargetRoughnessError = 0.05;
constexpr double kTargetSpecularError = 0.1;
constexpr double kTargetSheenError = 0.1;
// A map's constant is the mean of its float32 pixels: equal to the double it was filled with to
// float precision.
constexpr double kFloatMapTolerance = 1e-6;
// A measured map whose mean error exceeds this must not be reported as reliable (the stability
// suite's bound: a third of the 0..1 range, and the issue's specular target would be too strict
// a line between "off" and "fine" under model mismatch).
constexpr double kReliabilityErrorBound = 0.1;

// Two fabrics side by side: a near-grey matte-ish weave and a coloured, tinted, glossier one;
// base colour varies per pixel so that per-pixel colour matters.
PrincipledParams<double> TwoFabrics(int col, int row, int width, bool with_sheen) {
  PrincipledParams<double> p;
  const double texture = 1.0 + 0.08 * std::sin(0.9 * col + 0.4 * row);
  if (col < width / 2) {
    p.base_color = Eigen::Vector3d(0.50, 0.48, 0.45) * texture;
    p.roughness = 0.33;  // off the start grid, so the solver has to move
    p.specular = 0.55;
    p.sheen = with_sheen ? 0.6 : 0.0;
  } else {
    p.base_color = Eigen::Vector3d(0.60, 0.25, 0.10) * texture;
    p.roughness = 0.45;
    p.specular = 0.8;
    p.specular_tint = 0.5;
    p.sheen = with_sheen ? 0.3 : 0.0;
    p.sheen_tint = with_sheen ? 0.8 : 0.0;
  }
  return p;
}

double TruthValue(const PrincipledParams<double>& p, FitParameter parameter) {
  switch (parameter) {
    case FitParameter::kRoughness: return p.roughness;
    case FitParameter::kSpecular: return p.specular;
    case FitParameter::kSpecularTint: return p.specular_tint;
    case FitParameter::kSheen: return p.sheen;
    case FitParameter::kSheenTint: return p.sheen_tint;
    case FitParameter::kAnisotropic: return p.anisotropic;
    case FitParameter::kMetallic: return p.metallic;
  }
  return 0.0;
}

// Every fitted pixel's map value (or the report's value for a left-out map) against the truth.
void ExpectRecovered(const Scene& scene, const FitResult& result, FitParameter parameter, double tolerance) {
  const int width = scene.stack.grid.width;
  const Image& map = result.map(parameter);
  double worst = 0.0;
  for (std::size_t i = 0; i < scene.truth.size(); ++i) {
    const int row = static_cast<int>(i / width), col = static_cast<int>(i % width);
    if (result.cluster_id.at(0, row, col) < 0.0f) continue;
    const double fitted = map.empty() ? result.report(parameter).value : map.at(0, row, col);
    worst = std::max(worst, std::abs(fitted - TruthValue(scene.truth[i], parameter)));
  }
  EXPECT_LT(worst, tolerance) << FitParameterName(parameter);
}

// Mean absolute error of a parameter over fitted pixels (left-out maps count with their value).
double MeanAbsError(const Scene& scene, const FitResult& result, FitParameter parameter);

// Every measured map is reliable (clean data the model explains), or, with `bad_data`, every
// measured map off by more than kReliabilityErrorBound is flagged, with a reason.
void ExpectReliabilityVerdicts(const Scene& scene, const FitResult& result, bool bad_data) {
  for (int i = 0; i < kFitParameterCount; ++i) {
    const FitParameter p = static_cast<FitParameter>(i);
    const MapReport& m = result.report(p);
    if (!m.measured) continue;
    EXPECT_EQ(m.reliable, m.unreliable_reason.empty()) << FitParameterName(i);
    if (!bad_data) {
      EXPECT_TRUE(m.reliable) << FitParameterName(i) << ": " << m.unreliable_reason;
    } else if (MeanAbsError(scene, result, p) > kReliabilityErrorBound) {
      EXPECT_FALSE(m.reliable) << FitParameterName(i) << " off by " << MeanAbsError(scene, result, p)
                               << " and reported reliable";
    }
  }
}

double MeanAbsError(const Scene& scene, const FitResult& result, FitParameter parameter) {
  const int width = scene.stack.grid.width;
  const Image& map = result.map(parameter);
  double sum = 0.0;
  int n = 0;
  for (std::size_t i = 0; i < scene.truth.size(); ++i) {
    const int row = static_cast<int>(i / width), col = static_cast<int>(i % width);
    if (result.cluster_id.at(0, row, col) < 0.0f) continue;
    const double fitted = map.empty() ? result.report(parameter).value : map.at(0, row, col);
    sum += std::abs(fitted - TruthValue(scene.truth[i], parameter));
    ++n;
  }
  return n > 0 ? sum / n : 0.0;
}

void ExpectBaseColorRecovered(const Scene& scene, const FitResult& result) {
  const int width = scene.stack.grid.width;
  double worst = 0.0;
  for (std::size_t i = 0; i < scene.truth.size(); ++i) {
    const int row = static_cast<int>(i / width), col = static_cast<int>(i % width);
    for (int c = 0; c < 3; ++c) {
      worst = std::max(worst, std::abs(result.base_color.at(c, row, col) - scene.truth[i].base_color(c)));
    }
  }
  EXPECT_LT(worst, kExactColorTolerance);
}

// U3MSCAN_FIT_PRINT_JSON=1 prints each fit's report (docs/fitting.md quotes these figures).
void MaybePrint(const char* name, const FitResult& result) {
  if (std::getenv("U3MSCAN_FIT_PRINT_JSON") != nullptr) std::cout << "== " << name << "\n" << pipeline::FitResultToJson(result).dump(2) << "\n";
}

void ExpectFinite(const FitResult& result) {
  for (float v : result.base_color.data()) ASSERT_TRUE(std::isfinite(v));
  for (const Image& m : result.parameter_maps) {
    for (float v : m.data()) ASSERT_TRUE(std::isfinite(v));
  }
  for (const ClusterFit& c : result.clusters) {
    for (const ParameterEstimate& e : c.parameters) ASSERT_TRUE(std::isfinite(e.value));
    ASSERT_TRUE(std::isfinite(c.final_cost));
  }
}

// The stack without the observations of the given lights (their LightModels stay).
Stack WithoutLights(const Stack& stack, const std::set<int>& held_out) {
  Stack out = stack;
  out.observations.clear();
  for (const Observation& o : stack.observations) {
    if (!held_out.count(o.light)) out.observations.push_back(o);
  }
  return out;
}

// Sensor-like noise: each value times 1 + N(0, relative), from a fixed seed.
void AddRelativeNoise(double relative, unsigned seed, Stack* stack) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> noise(0.0f, static_cast<float>(relative));
  for (Observation& o : stack->observations) {
    for (float& v : o.rgb.data()) v *= 1.0f + noise(rng);
  }
}

class PrincipledFitTest : public ::testing::Test {
 protected:
  void SetUp() override { SetLogLevel(LogLevel::kWarning); }
};

TEST_F(PrincipledFitTest, OverheadRigRecoversEveryObservableLobeAndLeavesSheenOut) {
  SceneSpec spec;
  spec.lights_deg = OverheadLights();
  spec.material = [&](int col, int row) { return TwoFabrics(col, row, spec.width, false); };
  const Scene scene = MakeScene(spec);
  // Three lights held out of the fit for the re-render check.
  const std::set<int> held_out = {2, 7, 13};
  const Stack fit_stack = WithoutLights(scene.stack, held_out);
  const FitResult result = FitPrincipled(fit_stack, scene.geometry, FitOptions());
  MaybePrint("OverheadRigRecoversEveryObservableLobeAndLeavesSheenOut", result);

  ExpectFinite(result);
  EXPECT_TRUE(result.convergence.all_converged);
  EXPECT_GE(result.clusters.size(), 2u) << "two fabrics of different colour";
  ExpectRecovered(scene, result, FitParameter::kRoughness, kExactParameterTolerance);
  ExpectRecovered(scene, result, FitParameter::kSpecular, kExactParameterTolerance);
  ExpectRecovered(scene, result, FitParameter::kSpecularTint, kExactParameterTolerance);
  ExpectRecovered(scene, result, FitParameter::kAnisotropic, kExactParameterTolerance);
  ExpectBaseColorRecovered(scene, result);
  EXPECT_TRUE(result.report(FitParameter::kRoughness).measured);
  EXPECT_TRUE(result.report(FitParameter::kSpecularTint).measured) << "the coloured fabric shows tinted highlights";

  // Sheen cannot be seen from straight above: left out, no texture, default value, with a reason.
  const MapReport& sheen = result.report(FitParameter::kSheen);
  EXPECT_FALSE(sheen.measured);
  EXPECT_TRUE(result.map(FitParameter::kSheen).empty());
  EXPECT_EQ(sheen.value, 0.0);
  EXPECT_NE(sheen.reason.find("oblique"), std::string::npos) << sheen.reason;
  EXPECT_FALSE(result.report(FitParameter::kSheenTint).measured);
  EXPECT_FALSE(result.report(FitParameter::kMetallic).measured);
  ExpectReliabilityVerdicts(scene, result, /*bad_data=*/false);
  for (const ClusterFit& c : result.clusters) EXPECT_GT(c.highlight_share, 0.5) << "cluster " << c.id;

  // Lights left out of the fit re-render within the issue's 2 %.
  for (const Observation& o : scene.stack.observations) {
    if (!held_out.count(o.light)) continue;
    const Image rendered = RenderFitted(result, scene.stack, scene.geometry, o);
    EXPECT_LT(RelativeRmse(rendered, o.rgb), kHeldOutRelativeRmse) << "light " << o.light;
  }

  // fit.json lists what was left out (sheen, on this overhead rig) and the stage times.
  const nlohmann::ordered_json json = pipeline::FitResultToJson(result);
  ASSERT_TRUE(json["not_measured"].is_array());
  EXPECT_TRUE(std::any_of(json["not_measured"].begin(), json["not_measured"].end(),
                          [](const nlohmann::ordered_json& p) { return p["parameter"] == "sheen"; }));
  EXPECT_TRUE(json["times_s"]["total"].is_number());
}

TEST_F(PrincipledFitTest, ObliqueViewRecoversSheen) {
  SceneSpec spec;
  spec.lights_deg = OverheadAndGrazingLights();
  spec.oblique_view = true;
  spec.material = [&](int col, int row) { return TwoFabrics(col, row, spec.width, true); };
  const Scene scene = MakeScene(spec);
  const FitResult result = FitPrincipled(scene.stack, scene.geometry, FitOptions());
  MaybePrint("ObliqueViewRecoversSheen", result);

  ExpectFinite(result);
  EXPECT_TRUE(result.convergence.all_converged);
  EXPECT_TRUE(result.report(FitParameter::kSheen).measured) << result.report(FitParameter::kSheen).reason;
  EXPECT_TRUE(result.report(FitParameter::kSheenTint).measured) << result.report(FitParameter::kSheenTint).reason;
  for (FitParameter p : {FitParameter::kRoughness, FitParameter::kSpecular, FitParameter::kSpecularTint,
                         FitParameter::kSheen, FitParameter::kSheenTint}) {
    ExpectRecovered(scene, result, p, kExactParameterTolerance);
  }
  ExpectBaseColorRecovered(scene, result);
}

TEST_F(PrincipledFitTest, ReliefBelowThePixelIsFittedAsItsFacets) {
  // Bumps of 0.5 mm under pixels of 0.2 mm: each pixel holds 3 x 3 facets sloping up to 20 deg
  // apart, and both cameras photograph their mixture, each facet weighted by the area the camera
  // sees of it (test_scene.h, facets_per_pixel). Given the facets (the fine normals), the fit models
  // every photograph as that mixture and recovers the material; with the pixel's one normal (the
  // facets' mean) it reads the grazing 60 deg view's sheen and the lobes' width otherwise
  // (docs/fitting.md, "Facets of the finer grid"). Measured (mean abs error): sheen 0.0009 with the
  // facets, 0.334 with one normal; roughness 0.0000 and 0.166; specular 0.0007 and 0.047.
  constexpr double kOneNormalSheenBias = 0.1;  // the one-normal fit must be off by more than this
  constexpr double kExactModelRelativeRms = 1e-3;  // float32 images, solver tolerances
  constexpr double kTinyClusterTintError = 0.02;   // 3 pixels at 0.8, the rest exact: 0.009
  SceneSpec spec;
  spec.pitch_mm = 0.2;
  spec.bump_period_mm = 0.5;
  spec.bump_amplitude_mm = 0.03;
  spec.facets_per_pixel = 3;
  spec.lights_deg = OverheadAndGrazingLights();
  spec.oblique_view = true;
  spec.material = [&](int col, int row) { return TwoFabrics(col, row, spec.width, true); };
  const Scene scene = MakeScene(spec);
  const FitResult with_facets = FitPrincipled(scene.stack, scene.geometry, FitOptions());
  SurfaceGeometry one_normal = scene.geometry;
  one_normal.fine_normals = Image();
  const FitResult without = FitPrincipled(scene.stack, one_normal, FitOptions());
  MaybePrint("ReliefBelowThePixelIsFittedAsItsFacets (facets)", with_facets);
  MaybePrint("ReliefBelowThePixelIsFittedAsItsFacets (one normal)", without);
  for (FitParameter p : {FitParameter::kSheen, FitParameter::kRoughness, FitParameter::kSpecular}) {
    std::printf("[ MEASURED ] %s: mean abs error %.4f with facets, %.4f with one normal\n", FitParameterName(p),
                MeanAbsError(scene, with_facets, p), MeanAbsError(scene, without, p));
  }
  ExpectFinite(with_facets);
  EXPECT_TRUE(with_facets.convergence.all_converged);
  // The model is the render's: every cluster's residual vanishes (one normal: 0.05-0.22, flagged).
  for (const ClusterFit& c : with_facets.clusters) EXPECT_LT(c.rms_relative_residual, kExactModelRelativeRms) << c.id;
  EXPECT_FALSE(without.convergence.messages.empty()) << "the one-normal fit must report its mismatch";
  ASSERT_TRUE(with_facets.report(FitParameter::kSheen).measured) << with_facets.report(FitParameter::kSheen).reason;
  for (FitParameter p : {FitParameter::kRoughness, FitParameter::kSpecular, FitParameter::kSpecularTint,
                         FitParameter::kSheen}) {
    EXPECT_LT(MeanAbsError(scene, with_facets, p), kExactParameterTolerance) << FitParameterName(p);
  }
  // A cluster of 3 pixels (of 256) does not constrain its sheen tint (0.79 for 0.8, left out: 0).
  EXPECT_LT(MeanAbsError(scene, with_facets, FitParameter::kSheenTint), kTinyClusterTintError);
  ExpectBaseColorRecovered(scene, with_facets);
  EXPECT_GT(MeanAbsError(scene, without, FitParameter::kSheen), kOneNormalSheenBias)
      << "the scene must be one that a normal per pixel does not describe";
}

TEST_F(PrincipledFitTest, OverheadRigRecoversAnisotropy) {
  // Satin-like: highlights stretched along the grid x axis (the tangent convention).
  SceneSpec spec;
  spec.lights_deg = OverheadLights();
  spec.material = [](int col, int row) {
    PrincipledParams<double> p;
    p.base_color = Eigen::Vector3d(0.3, 0.32, 0.5) * (1.0 + 0.05 * std::sin(1.3 * col - 0.5 * row));
    p.roughness = 0.4;
    p.specular = 0.7;
    p.anisotropic = 0.6;
    return p;
  };
  const Scene scene = MakeScene(spec);
  const FitResult result = FitPrincipled(scene.stack, scene.geometry, FitOptions());
  MaybePrint("OverheadRigRecoversAnisotropy", result);
  ExpectFinite(result);
  EXPECT_TRUE(result.report(FitParameter::kAnisotropic).measured);
  for (FitParameter p : {FitParameter::kRoughness, FitParameter::kSpecular, FitParameter::kAnisotropic}) {
    ExpectRecovered(scene, result, p, kExactParameterTolerance);
  }
}

TEST_F(PrincipledFitTest, MetallicOnlyWhenTheDataDemandIt) {
  // A metallic thread (gold-coloured, no diffuse): the dielectric fit cannot explain it, the
  // metallic refit must. The fabric scenes above keep metallic at 0 ("not measured").
  SceneSpec spec;
  spec.lights_deg = OverheadLights();
  spec.material = [](int col, int row) {
    PrincipledParams<double> p;
    p.base_color = Eigen::Vector3d(0.9, 0.65, 0.3) * (1.0 + 0.04 * std::sin(0.8 * col + row));
    p.metallic = 1.0;
    p.roughness = 0.35;
    return p;
  };
  const Scene scene = MakeScene(spec);
  FitOptions options;
  options.clustering.cluster_count = 2;  // one material; each poorly fitted cluster costs a refit
  const FitResult result = FitPrincipled(scene.stack, scene.geometry, options);
  MaybePrint("MetallicOnlyWhenTheDataDemandIt", result);
  ExpectFinite(result);
  EXPECT_TRUE(result.report(FitParameter::kMetallic).measured) << result.report(FitParameter::kMetallic).reason;
  ExpectRecovered(scene, result, FitParameter::kMetallic, kExactParameterTolerance);
  ExpectRecovered(scene, result, FitParameter::kRoughness, kExactParameterTolerance);
}

TEST_F(PrincipledFitTest, UniformSampleUnderPointLightsGivesConstantMaps) {
  SceneSpec spec;
  spec.lights_deg = OverheadLights();
  spec.point_light_distance_mm = 30.0;  // near lights: direction and 1/d^2 vary over the 1.6 mm grid
  spec.material = [](int col, int row) {
    PrincipledParams<double> p;
    p.base_color = Eigen::Vector3d(0.4, 0.35, 0.3) * (1.0 + 0.05 * std::cos(0.7 * col * row));
    p.roughness = 0.35;
    p.specular = 0.6;
    return p;
  };
  const Scene scene = MakeScene(spec);
  std::map<std::string, double> progress;
  const FitResult result = FitPrincipled(scene.stack, scene.geometry, FitOptions(),
                                         [&](std::string_view stage, double fraction) {
                                           double& last = progress[std::string(stage)];
                                           EXPECT_GE(fraction, last) << stage;
                                           last = fraction;
                                         });
  MaybePrint("UniformSampleUnderPointLightsGivesConstantMaps", result);
  EXPECT_EQ(progress["fit: clusters"], 1.0);
  EXPECT_EQ(progress["fit: pixels"], 1.0);
  EXPECT_EQ(pipeline::FitResultToJson(result)["maps"]["specular"]["u3m"], "specular_value");
  const MapReport& roughness = result.report(FitParameter::kRoughness);
  EXPECT_TRUE(roughness.measured);
  EXPECT_TRUE(roughness.constant) << roughness.reason;
  EXPECT_NEAR(roughness.value, 0.35, kExactParameterTolerance);
  EXPECT_EQ(pipeline::FitResultToJson(result)["maps"]["roughness"]["texture"], false);
}

TEST_F(PrincipledFitTest, MeasuredIrradianceImagesTakePrecedence) {
  // Flat-field irradiance per observation (Observation::irradiance) must replace the analytic
  // light model: the analytic profile is made wrong, the images carry the truth.
  SceneSpec spec;
  spec.lights_deg = OverheadLights();
  spec.point_light_distance_mm = 30.0;
  spec.material = [](int col, int row) {
    PrincipledParams<double> p;
    p.base_color = Eigen::Vector3d(0.35, 0.4, 0.3) * (1.0 + 0.05 * std::sin(0.5 * col - row));
    p.roughness = 0.4;
    p.specular = 0.5;
    return p;
  };
  Scene scene = MakeScene(spec);
  for (Observation& o : scene.stack.observations) {
    const LightModel& light = scene.stack.lights[o.light];
    o.irradiance = Image(spec.width, spec.height, 1, 0.0f, spec.pitch_mm);
    for (int row = 0; row < spec.height; ++row) {
      for (int col = 0; col < spec.width; ++col) {
        const Eigen::Vector3d p = scene.stack.grid.PixelCentreInWorld(col, row, scene.geometry.height_mm.at(0, row, col));
        o.irradiance.at(0, row, col) = static_cast<float>(light.RelativeIrradianceAt(p));
      }
    }
  }
  for (LightModel& light : scene.stack.lights) light.profile_exponent = 200.0;  // wrong on purpose
  FitOptions options;
  options.clustering.cluster_count = 2;
  const FitResult result = FitPrincipled(scene.stack, scene.geometry, options);
  ExpectFinite(result);
  ExpectRecovered(scene, result, FitParameter::kRoughness, kExactParameterTolerance);
  ExpectRecovered(scene, result, FitParameter::kSpecular, kExactParameterTolerance);
  ExpectBaseColorRecovered(scene, result);
}

TEST_F(PrincipledFitTest, NoisyUniformSampleIsConstantNotNoise) {
  // 6 % noise: per-pixel refinement scatters roughness by its own uncertainty (beyond the absolute
  // tolerance of 0.01); a map whose spread is that noise must come out as a constant, not as a
  // texture of noise.
  SceneSpec spec;
  spec.lights_deg = OverheadLights();
  spec.material = [](int col, int row) {
    PrincipledParams<double> p;
    p.base_color = Eigen::Vector3d(0.45, 0.3, 0.25) * (1.0 + 0.05 * std::sin(0.9 * col + 0.3 * row));
    p.roughness = 0.3;
    p.specular = 0.6;
    return p;
  };
  Scene scene = MakeScene(spec);
  AddRelativeNoise(kHighNoiseRelative, 31, &scene.stack);
  FitOptions options;
  options.noise_relative = kHighNoiseRelative;  // the operator's noise model matches the sensor
  // One prior for every cluster: with the prior from the clusters' spread the pixels would hold
  // their cluster's value and leave the map rule nothing to do (AClusterOfOneValueHoldsIt...).
  options.pixel_prior_from_samples = false;
  const FitResult result = FitPrincipled(scene.stack, scene.geometry, options);
  MaybePrint("NoisyUniformSampleIsConstantNotNoise", result);
  EXPECT_TRUE(result.convergence.messages.empty()) << "noise alone is not a model mismatch";
  const MapReport& roughness = result.report(FitParameter::kRoughness);
  EXPECT_TRUE(roughness.measured);
  EXPECT_GT(roughness.spread, ObservabilityOptions().uniform_abs_tolerance) << "the test must exercise the rule";
  EXPECT_TRUE(roughness.constant) << roughness.reason << " spread " << roughness.spread;
  EXPECT_NEAR(roughness.value, 0.3, kTargetRoughnessError);
  // Specular is a cluster value: its clusters scatter within their noise, the map is one constant,
  // and every cluster was fitted with that constant (HoldUniformClusterMaps), measured there or not.
  const MapReport& specular = result.report(FitParameter::kSpecular);
  EXPECT_TRUE(specular.constant) << specular.reason;
  EXPECT_NE(specular.reason.find("over the clusters"), std::string::npos) << specular.reason;
  EXPECT_NEAR(specular.value, 0.6, kTargetSpecularError);
  int measuring = 0;
  for (const ClusterFit& c : result.clusters) {
    const ParameterEstimate& e = c.parameters[static_cast<int>(FitParameter::kSpecular)];
    measuring += e.measured ? 1 : 0;
    EXPECT_NEAR(e.value, specular.value, kFloatMapTolerance) << "cluster " << c.id;
  }
  EXPECT_GE(measuring, 2) << "the test must exercise the rule";
}

TEST_F(PrincipledFitTest, BoundsAreRespectedOnDataBeyondTheModel) {
  // Extreme truth (specular 1, base colour near 1) plus 5 % multiplicative noise pushes the
  // unconstrained optimum past the bounds.
  SceneSpec spec;
  spec.lights_deg = OverheadAndGrazingLights();
  spec.oblique_view = true;
  spec.material = [](int, int) {
    PrincipledParams<double> p;
    p.base_color = Eigen::Vector3d(0.98, 0.97, 0.99);
    p.roughness = 0.2;
    p.specular = 1.0;
    p.sheen = 1.0;
    return p;
  };
  Scene scene = MakeScene(spec);
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> noise(0.95f, 1.05f);
  for (Observation& o : scene.stack.observations) {
    for (float& v : o.rgb.data()) v *= noise(rng) * 1.05f;
  }
  FitOptions options;
  options.samples_per_cluster = 32;  // bounded noisy solves iterate long; keep the test fast
  options.clustering.cluster_count = 2;
  const FitResult result = FitPrincipled(scene.stack, scene.geometry, options);
  MaybePrint("BoundsAreRespectedOnDataBeyondTheModel", result);
  ExpectFinite(result);
  for (const ClusterFit& c : result.clusters) {
    for (const ParameterEstimate& e : c.parameters) {
      EXPECT_GE(e.value, 0.0);
      EXPECT_LE(e.value, 1.0);
    }
  }
  for (const Image& m : result.parameter_maps) {
    for (float v : m.data()) {
      EXPECT_GE(v, 0.0f);
      EXPECT_LE(v, 1.0f);
    }
  }
  for (float v : result.base_color.data()) {
    EXPECT_GE(v, 0.0f);
    EXPECT_LE(v, 1.0f);
  }
}

TEST_F(PrincipledFitTest, StiffMirrorLikeCaseConvergesOrFailsLoudlyWithoutNan) {
  SceneSpec spec;
  spec.lights_deg = OverheadLights();
  spec.white_level = 0.4;  // highlights of roughness 0.02 saturate and are flagged
  spec.material = [](int, int) {
    PrincipledParams<double> p;
    p.base_color = Eigen::Vector3d(0.3, 0.3, 0.35);
    p.roughness = 0.02;
    p.specular = 1.0;
    return p;
  };
  const Scene scene = MakeScene(spec);
  std::size_t saturated = 0;
  for (const Observation& o : scene.stack.observations) {
    for (std::uint8_t f : o.flags) saturated += (f & kSaturated) ? 1 : 0;
  }
  ASSERT_GT(saturated, 0u) << "the scene must contain flagged highlights";
  const FitResult result = FitPrincipled(scene.stack, scene.geometry, FitOptions());
  MaybePrint("StiffMirrorLikeCaseConvergesOrFailsLoudlyWithoutNan", result);
  ExpectFinite(result);
  if (result.convergence.all_converged) {
    const MapReport& roughness = result.report(FitParameter::kRoughness);
    ASSERT_TRUE(roughness.measured) << "the data exclude the default roughness 0.7: " << roughness.reason;
    EXPECT_LT(roughness.value, kStiffRoughnessBound);
    ExpectReliabilityVerdicts(scene, result, /*bad_data=*/true);
  } else {
    EXPECT_FALSE(result.convergence.messages.empty());
  }
}

TEST_F(PrincipledFitTest, DarkObservationAndMissingNormalsStayFinite) {
  SceneSpec spec;
  spec.width = 8;
  spec.height = 8;
  spec.lights_deg = OverheadLights();
  spec.material = [](int, int) { return PrincipledParams<double>(); };
  Scene scene = MakeScene(spec);
  for (float& v : scene.stack.observations[0].rgb.data()) v = 0.0f;  // a light that did not fire
  for (int c = 0; c < 3; ++c) scene.geometry.normals.at(c, 2, 3) = 0.0f;  // no normal: no data
  FitOptions options;
  options.noise_floor = 0.0;  // the weights must still be finite
  const FitResult result = FitPrincipled(scene.stack, scene.geometry, options);
  ExpectFinite(result);
  EXPECT_EQ(result.cluster_id.at(0, 2, 3), -1.0f);
  EXPECT_EQ(result.convergence.pixels_fitted, 63);
}

TEST_F(PrincipledFitTest, CastShadowFlaggedObservationsAreNotData) {
  // Issue 4: the pipeline marks cast shadows (reconstruction/cast_shadows.h) and the fit must leave
  // them out. Two stacks differ only inside the kCastShadow pixels of two lights (there: the true
  // render, or black with a bright speck); the fits must be identical, bit for bit.
  SceneSpec spec;
  spec.width = 8;
  spec.height = 8;
  spec.lights_deg = GrazingLights();
  spec.material = [](int, int) { return PrincipledParams<double>(); };
  Scene clean = MakeScene(spec);
  for (int k : {0, 3}) {
    Observation& o = clean.stack.observations[static_cast<std::size_t>(k)];
    o.flags.assign(o.rgb.pixel_count(), 0);
    for (std::size_t i = 0; i < o.flags.size(); i += 3) o.flags[i] |= kCastShadow;
  }
  Scene shadowed = clean;
  for (int k : {0, 3}) {
    Observation& o = shadowed.stack.observations[static_cast<std::size_t>(k)];
    const std::size_t n = o.rgb.pixel_count();
    for (std::size_t i = 0; i < n; i += 3)
      for (int c = 0; c < 3; ++c) o.rgb.data()[c * n + i] = (i % 2) ? 0.0f : 5.0f;
  }
  const FitResult a = FitPrincipled(clean.stack, clean.geometry, FitOptions());
  const FitResult b = FitPrincipled(shadowed.stack, shadowed.geometry, FitOptions());
  ExpectFinite(b);
  EXPECT_EQ(a.base_color.data(), b.base_color.data());
  for (int p = 0; p < kFitParameterCount; ++p) EXPECT_EQ(a.parameter_maps[p].data(), b.parameter_maps[p].data()) << p;
  ASSERT_EQ(a.clusters.size(), b.clusters.size());
  for (std::size_t c = 0; c < a.clusters.size(); ++c) {
    EXPECT_EQ(a.clusters[c].rms_relative_residual, b.clusters[c].rms_relative_residual);
  }
}

// Two fabrics on an 8 x 8 grid under the overhead lights: a fit small enough to run twice.
Scene SmallTwoFabricsOverhead() {
  SceneSpec spec;
  spec.width = 8;
  spec.height = 8;
  spec.lights_deg = OverheadLights();
  spec.material = [&](int col, int row) { return TwoFabrics(col, row, spec.width, false); };
  return MakeScene(spec);
}

TEST_F(PrincipledFitTest, RunsAreDeterministic) {
  const Scene scene = SmallTwoFabricsOverhead();
  const FitResult a = FitPrincipled(scene.stack, scene.geometry, FitOptions());
  const FitResult b = FitPrincipled(scene.stack, scene.geometry, FitOptions());
  EXPECT_EQ(a.base_color.data(), b.base_color.data());
  EXPECT_EQ(a.cluster_id.data(), b.cluster_id.data());
  for (int i = 0; i < kFitParameterCount; ++i) EXPECT_EQ(a.parameter_maps[i].data(), b.parameter_maps[i].data());
}

// The cluster model FitPrincipled hands back (pipeline/top_view_normals.h refines further pixels
// with it) is the one its maps were made from: the per-pixel step run again with it on the same
// stack gives the same maps, and the fit with the model kept is the fit without.
TEST_F(PrincipledFitTest, TheModelHandedBackMakesTheSameMapsAgain) {
  const Scene scene = SmallTwoFabricsOverhead();
  ClusterModel model;
  const FitResult kept = FitPrincipled(scene.stack, scene.geometry, FitOptions(), {}, &model);
  const FitResult plain = FitPrincipled(scene.stack, scene.geometry, FitOptions());
  ASSERT_EQ(model.clusters.size(), kept.clusters.size());
  EXPECT_EQ(kept.base_color.data(), plain.base_color.data());
  FitResult again = StartPixelMaps(model, scene.stack.grid);
  PixelTally tally;
  FitPixelRows(model, scene.stack, scene.geometry, 0, &again, &tally);
  FinishPixelMaps(model, tally, &again);
  EXPECT_EQ(again.base_color.data(), kept.base_color.data());
  EXPECT_EQ(again.cluster_id.data(), kept.cluster_id.data());
  int maps = 0;
  for (int i = 0; i < kFitParameterCount; ++i) {
    EXPECT_EQ(again.parameter_maps[i].data(), kept.parameter_maps[i].data()) << "parameter " << i;
    EXPECT_EQ(plain.parameter_maps[i].data(), kept.parameter_maps[i].data()) << "parameter " << i;
    maps += kept.parameter_maps[i].empty() ? 0 : 1;
  }
  EXPECT_GT(maps, 0);  // the comparison held some map
}

TEST_F(PrincipledFitTest, MismatchedInputsAreRejected) {
  SceneSpec spec;
  spec.width = 4;
  spec.height = 4;
  spec.lights_deg = {{45.0, 0.0}};
  spec.material = [](int, int) { return PrincipledParams<double>(); };
  const Scene scene = MakeScene(spec);
  SurfaceGeometry bad = scene.geometry;
  bad.normals = Image(3, 4, 3);
  EXPECT_THROW(FitPrincipled(scene.stack, bad, FitOptions()), std::invalid_argument);
  Stack stack = scene.stack;
  stack.observations[0].light = 5;
  EXPECT_THROW(FitPrincipled(stack, scene.geometry, FitOptions()), std::invalid_argument);
  FitOptions options;
  options.noise_relative = -1.0;
  EXPECT_THROW(FitPrincipled(scene.stack, scene.geometry, options), std::invalid_argument);
  // Fine normals must cover the grid fine_factor times over, with a factor the facets support.
  SurfaceGeometry fine = scene.geometry;
  fine.fine_normals = Image(8, 8, 3);
  fine.fine_factor = 3;
  EXPECT_THROW(FitPrincipled(scene.stack, fine, FitOptions()), std::invalid_argument);
  FitResult fitted;
  fitted.base_color = Image(4, 4, 3);
  fitted.cluster_id = Image(4, 4, 1);
  EXPECT_NO_THROW(RenderFitted(fitted, scene.stack, scene.geometry, scene.stack.observations[0]));
  EXPECT_THROW(RenderFitted(fitted, scene.stack, fine, scene.stack.observations[0]), std::invalid_argument);
  fine.fine_factor = 1;
  EXPECT_THROW(FitPrincipled(scene.stack, fine, FitOptions()), std::invalid_argument);
}

// The issue's accuracy targets on a capture with sensor-like noise: 1 % Gaussian per channel
// (seeded), oblique rig, four lights held out of the fit (constants at the top of the file).
// Held-out images compared with the noise-free truth: noise does not count against the fit.

TEST_F(PrincipledFitTest, NoisyCaptureMeetsTheIssueTargets) {
  SceneSpec spec;
  spec.lights_deg = OverheadAndGrazingLights();
  spec.oblique_view = true;
  spec.material = [&](int col, int row) { return TwoFabrics(col, row, spec.width, true); };
  const Scene scene = MakeScene(spec);
  const std::set<int> held_out = {1, 6, 11, 18};
  Stack noisy = WithoutLights(scene.stack, held_out);
  AddRelativeNoise(kNoiseRelative, 23, &noisy);
  FitOptions options;
  options.samples_per_cluster = 48;  // noisy solves iterate long; keep the test fast
  const FitResult result = FitPrincipled(noisy, scene.geometry, options);
  MaybePrint("NoisyCaptureMeetsTheIssueTargets", result);
  ExpectFinite(result);
  const double roughness = MeanAbsError(scene, result, FitParameter::kRoughness);
  const double specular = MeanAbsError(scene, result, FitParameter::kSpecular);
  const double sheen = MeanAbsError(scene, result, FitParameter::kSheen);
  EXPECT_TRUE(result.report(FitParameter::kSheen).measured);
  EXPECT_LT(roughness, kTargetRoughnessError);
  EXPECT_LT(specular, kTargetSpecularError);
  EXPECT_LT(sheen, kTargetSheenError);
  double worst_rmse = 0.0;
  for (const Observation& o : scene.stack.observations) {
    if (!held_out.count(o.light)) continue;
    const double rmse = RelativeRmse(RenderFitted(result, scene.stack, scene.geometry, o), o.rgb);
    worst_rmse = std::max(worst_rmse, rmse);
    if (std::getenv("U3MSCAN_FIT_PRINT_JSON") != nullptr) std::cout << "held-out view " << o.view << " light " << o.light << " rmse " << rmse << "\n";
  }
  EXPECT_LT(worst_rmse, kHeldOutRelativeRmse);
  if (std::getenv("U3MSCAN_FIT_PRINT_JSON") != nullptr) {
    std::cout << "noisy: mean |error| roughness " << roughness << ", specular " << specular << ", sheen " << sheen
              << ", specular_tint " << MeanAbsError(scene, result, FitParameter::kSpecularTint) << ", sheen_tint "
              << MeanAbsError(scene, result, FitParameter::kSheenTint) << "; worst held-out relative RMSE "
              << worst_rmse << "\n";
  }
}

// The per-pixel step's prior from each cluster's own spread (FitOptions::pixel_prior_from_samples,
// docs/fitting.md "Per-pixel spread from the samples"). Two fabrics, each of one roughness, under
// 2 % noise: each cluster's estimated spread is near 0, so its pixels hold its value instead of
// writing their noise into the map; with one prior std of 0.1 for every cluster they scatter.
constexpr double kSpreadTestNoise = 0.02;
// A cluster of one value: the spread found beyond the noise (parameter units).
constexpr double kUniformClusterSpread = 0.01;

TEST_F(PrincipledFitTest, AClusterOfOneValueHoldsItInsteadOfItsPixelsNoise) {
  SceneSpec spec;
  spec.lights_deg = OverheadLights();
  spec.material = [&](int col, int row) { return TwoFabrics(col, row, spec.width, false); };
  Scene scene = MakeScene(spec);
  AddRelativeNoise(kSpreadTestNoise, 11, &scene.stack);
  FitOptions one_prior;
  one_prior.pixel_prior_from_samples = false;
  const FitResult with_spread = FitPrincipled(scene.stack, scene.geometry, FitOptions());
  const FitResult with_one_prior = FitPrincipled(scene.stack, scene.geometry, one_prior);
  MaybePrint("AClusterOfOneValueHoldsItInsteadOfItsPixelsNoise", with_spread);
  ExpectFinite(with_spread);
  for (const ClusterFit& c : with_spread.clusters) {
    if (!c.parameters[kRoughness].measured) continue;
    EXPECT_LT(c.pixel_prior_std[kRoughness], kUniformClusterSpread) << "cluster " << c.id;
  }
  for (const ClusterFit& c : with_one_prior.clusters) {
    if (!c.parameters[kRoughness].measured) continue;
    EXPECT_EQ(c.pixel_prior_std[kRoughness], one_prior.pixel_prior_std) << "cluster " << c.id;
  }
  const double error = MeanAbsError(scene, with_spread, FitParameter::kRoughness);
  const double one_prior_error = MeanAbsError(scene, with_one_prior, FitParameter::kRoughness);
  if (std::getenv("U3MSCAN_FIT_PRINT_JSON") != nullptr) {
    std::cout << "roughness mean |error|: prior from the clusters' spread " << error << ", one prior " << one_prior_error << "\n";
  }
  EXPECT_LT(error, 0.5 * one_prior_error) << "the pixels' noise is not written into the map";
}

// A matte fabric whose threads differ in roughness (a denim's warp, 0.74-0.96 in the synthetic
// scanner's scene): one cluster by appearance, threads 2 px wide along y.
constexpr double kSmoothThread = 0.74, kRoughThread = 0.96;
// Relative, per channel: a broad lobe's pixel is pinned to within its spread only at low noise
// (a 4x camera's map pixel averages 16 camera pixels' noise).
constexpr double kThreadTestNoise = 0.005;
PrincipledParams<double> ThreadOfTwoRoughnesses(int col) {
  PrincipledParams<double> p;
  p.base_color = Eigen::Vector3d(0.12, 0.16, 0.30);
  p.roughness = (col / 2) % 2 == 0 ? kSmoothThread : kRoughThread;
  p.specular = 0.4;
  return p;
}

// The threads on a nearly flat sample. The cluster's samples show the spread, so the per-pixel
// step follows the threads.
TEST_F(PrincipledFitTest, AClusterWhosePixelsDifferFollowsThem) {
  SceneSpec spec;
  spec.width = 24;
  spec.height = 24;
  spec.bump_amplitude_mm = 0.01;
  spec.lights_deg = OverheadLights();
  spec.material = [](int col, int) { return ThreadOfTwoRoughnesses(col); };
  Scene scene = MakeScene(spec);
  AddRelativeNoise(kThreadTestNoise, 7, &scene.stack);
  const FitResult result = FitPrincipled(scene.stack, scene.geometry, FitOptions());
  MaybePrint("AClusterWhosePixelsDifferFollowsThem", result);
  ExpectFinite(result);
  ASSERT_TRUE(result.report(FitParameter::kRoughness).measured);
  for (const ClusterFit& c : result.clusters) {
    if (!c.parameters[kRoughness].measured) continue;
    EXPECT_GT(c.pixel_prior_std[kRoughness], 0.25 * (kRoughThread - kSmoothThread)) << "cluster " << c.id;
  }
  const Image& roughness = result.map(FitParameter::kRoughness);
  ASSERT_FALSE(roughness.empty()) << "two thread roughnesses 0.22 apart are not a constant";
  double sum[2] = {0.0, 0.0};
  int n[2] = {0, 0};
  for (int row = 0; row < spec.height; ++row) {
    for (int col = 0; col < spec.width; ++col) {
      const int rough = (col / 2) % 2;
      sum[rough] += roughness.at(0, row, col);
      ++n[rough];
    }
  }
  const double smooth_mean = sum[0] / n[0], rough_mean = sum[1] / n[1];
  if (std::getenv("U3MSCAN_FIT_PRINT_JSON") != nullptr) {
    std::cout << "threads: roughness mean " << smooth_mean << " for " << kSmoothThread << ", " << rough_mean << " for "
              << kRoughThread << "; mean |error| " << MeanAbsError(scene, result, FitParameter::kRoughness) << "\n";
  }
  EXPECT_GT(rough_mean - smooth_mean, 0.5 * (kRoughThread - kSmoothThread)) << "the map follows the threads";
  EXPECT_LT(MeanAbsError(scene, result, FitParameter::kRoughness), kTargetRoughnessError);
}

// Mean angle (degrees) between the fit's refined normals and the scene's true ones.
double MeanNormalErrorDeg(const Scene& scene, const FitResult& result) {
  const Image& truth = scene.geometry.normals;
  double sum = 0.0;
  int n = 0;
  for (int row = 0; row < truth.height(); ++row) {
    for (int col = 0; col < truth.width(); ++col) {
      const Eigen::Vector3d a(truth.at(0, row, col), truth.at(1, row, col), truth.at(2, row, col));
      const Eigen::Vector3d b(result.normals.at(0, row, col), result.normals.at(1, row, col), result.normals.at(2, row, col));
      sum += std::atan2(a.cross(b).norm(), a.dot(b)) / testing::kDegToRad;
      ++n;
    }
  }
  return sum / n;
}

// The same threads on a relief whose facets tilt up to 27 degrees, the geometry's normals true.
// At its cluster's one lobe a thread's normal bends to explain the lobe it does not have (a
// smoother thread's stronger highlight reads as a tilt toward the light); refined with its own
// lobe in one solve (FitOptions::refine_normal_with_lobe) it stays near the truth, and its lobe
// with it.
TEST_F(PrincipledFitTest, AThreadsNormalIsRefinedWithItsOwnLobe) {
  // What the joint solve must gain at least: the normals' and the roughness' mean error, each a
  // fraction of the two steps one after the other.
  constexpr double kJointNormalGain = 0.5, kJointRoughnessGain = 0.75;
  SceneSpec spec;
  spec.width = 24;
  spec.height = 24;
  spec.lights_deg = OverheadLights();
  spec.material = [](int col, int) { return ThreadOfTwoRoughnesses(col); };
  Scene scene = MakeScene(spec);
  AddRelativeNoise(kThreadTestNoise, 7, &scene.stack);
  FitOptions one_after_the_other;
  one_after_the_other.refine_normal_with_lobe = false;
  const FitResult joint = FitPrincipled(scene.stack, scene.geometry, FitOptions());
  const FitResult steps = FitPrincipled(scene.stack, scene.geometry, one_after_the_other);
  MaybePrint("AThreadsNormalIsRefinedWithItsOwnLobe", joint);
  ExpectFinite(joint);
  ASSERT_FALSE(joint.normals.empty());
  const double joint_normals = MeanNormalErrorDeg(scene, joint), step_normals = MeanNormalErrorDeg(scene, steps);
  const double joint_roughness = MeanAbsError(scene, joint, FitParameter::kRoughness);
  const double step_roughness = MeanAbsError(scene, steps, FitParameter::kRoughness);
  if (std::getenv("U3MSCAN_FIT_PRINT_JSON") != nullptr) {
    std::cout << "normals mean error (deg): joint " << joint_normals << ", one after the other " << step_normals
              << "; roughness mean |error|: joint " << joint_roughness << ", one after the other " << step_roughness
              << "\n";
  }
  EXPECT_LT(joint_normals, kJointNormalGain * step_normals);
  EXPECT_LT(joint_roughness, kJointRoughnessGain * step_roughness);
  EXPECT_LT(joint_roughness, kTargetRoughnessError);
}

// Model mismatch (the issue asks for the same figures): the render's sheen is Charlie sheen, which
// the Principled model cannot represent (it is visible even from overhead, where Disney sheen is
// not). The figures are printed with U3MSCAN_FIT_PRINT_JSON=1 and quoted in docs/fitting.md; the
// test checks that the fit stays finite and that the report flags the misfit instead of hiding it.
constexpr double kMismatchFlagRelativeRms = 0.05;
// The hidden-lobe rule's bound: sqrt of GGX's alpha clamp (the fit's lower bound), 0.032.
constexpr double kHiddenLobeRuleBound = 0.032;

// A cluster fit with every parameter unmeasured at its U3M default (std inf), for the rules'
// unit tests to set what they need.
ClusterFit ClusterAtDefaults(int id) {
  ClusterFit c;
  c.id = id;
  for (int i = 0; i < kFitParameterCount; ++i) {
    c.parameters[i].value = FitParameterDefault(static_cast<FitParameter>(i));
    c.parameters[i].std_dev = std::numeric_limits<double>::infinity();
  }
  return c;
}

// Hidden lobe (docs/fitting.md): roughness at the lower bound while specular is held at its
// default is a held lobe shrunk between the lights (twill / near: roughness 0 for 0.71), not a
// measurement, unless the capture has saturated highlights (the mirror-like case, kept measured:
// StiffMirrorLikeCaseConvergesOrFailsLoudlyWithoutNan runs the rule on such a capture).
TEST(HiddenLobeRule, RoughnessAtTheLowerBoundWithSpecularHeldIsLeftOut) {
  auto cluster = [](int id, double roughness, bool specular_measured) {
    ClusterFit c = ClusterAtDefaults(id);
    ParameterEstimate& r = c.parameters[static_cast<int>(FitParameter::kRoughness)];
    r.value = roughness;
    r.std_dev = 0.03;
    r.measured = true;
    ParameterEstimate& s = c.parameters[static_cast<int>(FitParameter::kSpecular)];
    s.measured = specular_measured;
    if (specular_measured) s.std_dev = 0.02;
    return c;
  };
  const std::vector<ClusterFit> clusters = {cluster(0, 0.0, false),   // the twill / near case
                                            cluster(1, kHiddenLobeRuleBound, false),
                                            cluster(2, 0.02, true),   // specular measured: a real narrow lobe
                                            cluster(3, 0.05, false)};  // above the bound
  std::vector<ClusterFit> without_saturation = clusters;
  EXPECT_EQ(LeaveOutHiddenLobeRoughness(false, &without_saturation), (std::vector<int>{0, 1}));
  for (int id : {0, 1}) {
    const ParameterEstimate& r = without_saturation[id].parameters[static_cast<int>(FitParameter::kRoughness)];
    EXPECT_FALSE(r.measured);
    EXPECT_TRUE(std::isinf(r.std_dev));
    EXPECT_NE(r.reason.find("lower bound"), std::string::npos) << r.reason;
  }
  for (int id : {2, 3}) {
    EXPECT_TRUE(without_saturation[id].parameters[static_cast<int>(FitParameter::kRoughness)].measured);
  }
  std::vector<ClusterFit> with_saturation = clusters;
  EXPECT_TRUE(LeaveOutHiddenLobeRoughness(true, &with_saturation).empty());
  for (const ClusterFit& c : with_saturation) {
    EXPECT_TRUE(c.parameters[static_cast<int>(FitParameter::kRoughness)].measured) << "cluster " << c.id;
  }
}

// The maps as a whole (docs/fitting.md): a parameter every cluster keeps (each within twice max_std
// at its final solution) but whose pooled std is above max_std is left out of every cluster, and
// the clusters that measured it are fitted again with it at its default (denim on the near rig:
// the values fitted beside a dropped specular re-rendered 44.5 % off, refitted 18.6 %).
ClusterFit PooledRuleCluster(int id, double roughness_std, double specular_std) {
  ClusterFit c = ClusterAtDefaults(id);
  c.rms_relative_residual = 0.01;
  for (ParameterEstimate& e : c.parameters) e.reason = "own reason of cluster " + std::to_string(id);
  auto set = [&](FitParameter p, double value, double std_dev) {
    ParameterEstimate& e = c.parameters[static_cast<int>(p)];
    e.value = value;
    e.std_dev = std_dev;
    e.measured = std::isfinite(std_dev);
    if (e.measured) e.reason.clear();
  };
  set(FitParameter::kRoughness, 0.8, roughness_std);
  set(FitParameter::kSpecular, 0.3, specular_std);
  return c;
}

TEST(MapsAsAWholeRule, APoolPoorlyKnownParameterIsLeftOutAndItsClustersFittedAgainWithout) {
  const FitOptions options;  // max_std 0.05
  const int specular = static_cast<int>(FitParameter::kSpecular);
  const int roughness = static_cast<int>(FitParameter::kRoughness);
  // Pooled specular std sqrt((0.04^2 + 0.07^2) / 2) = 0.057 > 0.05; cluster 2 does not measure it.
  std::vector<ClusterFit> clusters = {PooledRuleCluster(0, 0.01, 0.04), PooledRuleCluster(1, 0.01, 0.07),
                                      PooledRuleCluster(2, 0.01, std::numeric_limits<double>::infinity())};
  std::vector<std::pair<int, ParameterMask>> calls;
  std::mutex calls_mutex;
  LeaveOutMapsNotKnownAsAWhole(options, {100, 100, 100}, &clusters, [&](int id, const ParameterMask& left_out) {
    std::lock_guard lock(calls_mutex);
    calls.emplace_back(id, left_out);
    clusters[id].parameters[roughness].value = 0.9;  // what a refit with specular at 0.5 moves
  });
  std::sort(calls.begin(), calls.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  ASSERT_EQ(calls.size(), 2u) << "only the clusters that measured specular are fitted again";
  for (int j = 0; j < 2; ++j) {
    EXPECT_EQ(calls[j].first, j);
    ParameterMask expected{};
    expected[specular] = true;
    EXPECT_EQ(calls[j].second, expected) << "cluster " << j << ": only specular is held at its default";
  }
  for (const ClusterFit& c : clusters) {
    const ParameterEstimate& s = c.parameters[specular];
    EXPECT_FALSE(s.measured) << "cluster " << c.id;
    EXPECT_TRUE(std::isinf(s.std_dev)) << "cluster " << c.id;
    EXPECT_DOUBLE_EQ(s.value, FitParameterDefault(FitParameter::kSpecular)) << "cluster " << c.id;
    EXPECT_TRUE(c.parameters[roughness].measured) << "cluster " << c.id;
  }
  EXPECT_NE(clusters[0].parameters[specular].reason.find("pooled over the clusters 0.057 > 0.05; worst cluster 1: 0.07"),
            std::string::npos)
      << clusters[0].parameters[specular].reason;
  EXPECT_EQ(clusters[2].parameters[specular].reason, "own reason of cluster 2");
  EXPECT_DOUBLE_EQ(clusters[0].parameters[roughness].value, 0.9) << "the refit's values are kept";
  EXPECT_DOUBLE_EQ(clusters[2].parameters[roughness].value, 0.8) << "a cluster not fitted again is not touched";
}

TEST(MapsAsAWholeRule, PixelWeightsDecideAndAWellKnownPoolIsLeftAlone) {
  const FitOptions options;
  // Weights 9 : 1 pool the same stds to sqrt((9 * 0.04^2 + 0.07^2) / 10) = 0.044 <= 0.05.
  std::vector<ClusterFit> clusters = {PooledRuleCluster(0, 0.01, 0.04), PooledRuleCluster(1, 0.01, 0.07)};
  const std::vector<ClusterFit> before = clusters;
  int calls = 0;
  LeaveOutMapsNotKnownAsAWhole(options, {900, 100}, &clusters, [&](int, const ParameterMask&) { ++calls; });
  EXPECT_EQ(calls, 0);
  for (const ClusterFit& c : clusters) EXPECT_TRUE(c.parameters[static_cast<int>(FitParameter::kSpecular)].measured);
  // A cluster the model does not explain does not count in the pool (it is left out whole later).
  clusters = before;
  clusters[0].rms_relative_residual = options.unusable_relative_rms * 2.0;
  LeaveOutMapsNotKnownAsAWhole(options, {900, 100}, &clusters, [&](int, const ParameterMask&) { ++calls; });
  EXPECT_EQ(calls, 1) << "cluster 1 alone pools to 0.07: specular is left out; cluster 0 is not fitted again";
  for (const ClusterFit& c : clusters) EXPECT_FALSE(c.parameters[static_cast<int>(FitParameter::kSpecular)].measured);
}

TEST(MapsAsAWholeRule, ARefitThatLeavesAnotherParameterPoorlyKnownLeavesItOutToo) {
  const FitOptions options;
  const int specular = static_cast<int>(FitParameter::kSpecular);
  const int roughness = static_cast<int>(FitParameter::kRoughness);
  std::vector<ClusterFit> clusters = {PooledRuleCluster(0, 0.01, 0.09), PooledRuleCluster(1, 0.01, 0.09)};
  std::vector<ParameterMask> rounds;
  std::mutex rounds_mutex;
  LeaveOutMapsNotKnownAsAWhole(options, {1, 1}, &clusters, [&](int id, const ParameterMask& left_out) {
    std::lock_guard lock(rounds_mutex);
    if (id == 0) rounds.push_back(left_out);
    clusters[id].parameters[roughness].std_dev = 0.08;  // without specular the roughness loses its anchor
  });
  ASSERT_EQ(rounds.size(), 2u);
  EXPECT_TRUE(rounds[0][specular] && !rounds[0][roughness]);
  EXPECT_TRUE(rounds[1][specular] && rounds[1][roughness]) << "the second refit holds both";
  for (const ClusterFit& c : clusters) {
    EXPECT_FALSE(c.parameters[specular].measured);
    EXPECT_FALSE(c.parameters[roughness].measured);
    EXPECT_DOUBLE_EQ(c.parameters[roughness].value, FitParameterDefault(FitParameter::kRoughness));
  }
}

// Uniform within noise (docs/fitting.md): a map of cluster values that spread no more than their
// noise is one constant, and the clusters are fitted again with it held there, so that their other
// values belong with it (moving the values after the fit broke the joint fit: denim, near rig,
// balanced, re-render 18.6 -> 38.5 %).
ClusterFit UniformRuleCluster(int id, double specular, double sheen) {
  ClusterFit c = PooledRuleCluster(id, 0.01, 0.04);
  c.parameters[static_cast<int>(FitParameter::kSpecular)].value = specular;
  ParameterEstimate& s = c.parameters[static_cast<int>(FitParameter::kSheen)];
  s = {sheen, 0.03, true, "", true, ""};
  return c;
}

TEST(UniformClusterMaps, ClustersWithinNoiseAreFittedAgainAtTheWeightedMean) {
  const FitOptions options;  // per pixel: roughness is refined per pixel, its map is not the clusters'
  const int specular = static_cast<int>(FitParameter::kSpecular);
  const int roughness = static_cast<int>(FitParameter::kRoughness);
  const int sheen = static_cast<int>(FitParameter::kSheen);
  // Specular 0.5 / 0.6 / 0.545 (std 0.04 each) and cluster 3, which did not measure it: its pixels
  // hold the default 0.5. Weights 1 : 1 : 2 : 1: mean 0.538, spread 0.037 <= 2 x 0.04. Sheen
  // 0.1 / 0.5 / 0.3 / 0.3 (std 0.03): spread 0.13, a real texture.
  std::vector<ClusterFit> clusters = {UniformRuleCluster(0, 0.5, 0.1), UniformRuleCluster(1, 0.6, 0.5),
                                      UniformRuleCluster(2, 0.545, 0.3), UniformRuleCluster(3, 0.9, 0.3)};
  clusters[2].parameters[specular].reliable = false;
  clusters[2].parameters[specular].unreliable_reason = "own flag";
  clusters[3].parameters[specular] = {0.9, std::numeric_limits<double>::infinity(), false, "own reason", true, ""};
  const double mean = (0.5 + 0.6 + 2 * 0.545 + 0.5) / 5.0;
  std::vector<int> refitted;
  std::mutex refitted_mutex;
  const auto verdict = HoldUniformClusterMaps(
      options, {100, 100, 200, 100}, &clusters, [&](int id, const ParameterMask& held, const ParameterVector& values) {
        std::lock_guard lock(refitted_mutex);
        refitted.push_back(id);
        ParameterMask expected{};
        expected[specular] = true;
        EXPECT_EQ(held, expected) << "cluster " << id;
        EXPECT_DOUBLE_EQ(values[specular], mean);
        ParameterEstimate& s = clusters[id].parameters[specular];
        s = {values[specular], std::numeric_limits<double>::infinity(), false, "held", true, ""};  // as FitCluster
        clusters[id].parameters[roughness].value = 0.7;  // what a refit with the held specular moves
      });
  std::sort(refitted.begin(), refitted.end());
  EXPECT_EQ(refitted, (std::vector<int>{0, 1, 3})) << "cluster 2 is within the absolute tolerance of the mean";
  EXPECT_NE(verdict[specular].find("uniform within noise over the clusters"), std::string::npos) << verdict[specular];
  EXPECT_TRUE(verdict[sheen].empty()) << verdict[sheen];
  EXPECT_TRUE(verdict[roughness].empty()) << "refined per pixel: judged on the pixels' map";
  for (const ClusterFit& c : clusters) {
    const ParameterEstimate& s = c.parameters[specular];
    EXPECT_DOUBLE_EQ(s.value, mean) << "cluster " << c.id << ": its pixels hold the constant";
    if (c.id == 3) continue;
    EXPECT_TRUE(s.measured) << "cluster " << c.id;
    EXPECT_DOUBLE_EQ(s.std_dev, 0.04) << "cluster " << c.id << " keeps its own std";
  }
  EXPECT_FALSE(clusters[3].parameters[specular].measured) << "held is not measured";
  EXPECT_EQ(clusters[3].parameters[specular].reason, "own reason");
  EXPECT_FALSE(clusters[2].parameters[specular].reliable) << "and its own reliability";
  EXPECT_DOUBLE_EQ(clusters[0].parameters[roughness].value, 0.7) << "the refit's values are kept";
  EXPECT_DOUBLE_EQ(clusters[2].parameters[roughness].value, 0.8);
  EXPECT_DOUBLE_EQ(clusters[1].parameters[sheen].value, 0.5) << "a texture keeps its cluster values";
}

TEST(UniformClusterMaps, SpreadBeyondNoiseAndUnusableClustersAreLeftAlone) {
  FitOptions options;
  options.mode = FitMode::kClusters;  // roughness is a cluster value too
  const int specular = static_cast<int>(FitParameter::kSpecular);
  const int roughness = static_cast<int>(FitParameter::kRoughness);
  // Specular 0.3 / 0.5 (std 0.04): spread 0.1 > 0.08. Roughness 0.8 in both: uniform, nothing moves.
  std::vector<ClusterFit> clusters = {UniformRuleCluster(0, 0.3, 0.0), UniformRuleCluster(1, 0.5, 0.0),
                                      UniformRuleCluster(2, 0.9, 0.0)};
  clusters[2].rms_relative_residual = options.unusable_relative_rms * 2.0;  // would spread the pool further
  clusters[2].parameters[roughness].value = 0.2;                            // would make roughness a texture
  int calls = 0;
  const auto verdict = HoldUniformClusterMaps(options, {1, 1, 1}, &clusters,
                                              [&](int, const ParameterMask&, const ParameterVector&) { ++calls; });
  EXPECT_EQ(calls, 0);
  EXPECT_TRUE(verdict[specular].empty()) << verdict[specular];
  EXPECT_FALSE(verdict[roughness].empty()) << "uniform: every usable cluster at 0.8";
  EXPECT_DOUBLE_EQ(clusters[0].parameters[specular].value, 0.3);
  EXPECT_DOUBLE_EQ(clusters[1].parameters[specular].value, 0.5);
  EXPECT_DOUBLE_EQ(clusters[2].parameters[roughness].value, 0.2) << "the unusable cluster is not held";
}

TEST(UniformClusterMaps, ARefitThatMakesAnotherMapUniformHoldsItToo) {
  const FitOptions options;
  const int specular = static_cast<int>(FitParameter::kSpecular);
  const int sheen = static_cast<int>(FitParameter::kSheen);
  std::vector<ClusterFit> clusters = {UniformRuleCluster(0, 0.45, 0.2), UniformRuleCluster(1, 0.55, 0.6)};
  std::vector<ParameterMask> rounds;
  std::mutex rounds_mutex;
  const auto verdict = HoldUniformClusterMaps(
      options, {1, 1}, &clusters, [&](int id, const ParameterMask& held, const ParameterVector& values) {
        std::lock_guard lock(rounds_mutex);
        if (id == 0) rounds.push_back(held);
        clusters[id].parameters[specular].measured = false;  // held, as FitCluster reports it
        if (!held[sheen]) clusters[id].parameters[sheen].value = id == 0 ? 0.38 : 0.42;  // the fit with specular held
        EXPECT_DOUBLE_EQ(values[specular], 0.5);
      });
  ASSERT_EQ(rounds.size(), 2u);
  EXPECT_TRUE(rounds[0][specular] && !rounds[0][sheen]);
  EXPECT_TRUE(rounds[1][specular] && rounds[1][sheen]) << "the second refit holds both";
  EXPECT_FALSE(verdict[sheen].empty());
  for (const ClusterFit& c : clusters) {
    EXPECT_TRUE(c.parameters[specular].measured) << "held again after the second refit, cluster " << c.id;
    EXPECT_DOUBLE_EQ(c.parameters[specular].value, 0.5);
    EXPECT_DOUBLE_EQ(c.parameters[sheen].value, 0.4);
  }
}

// The maps' decisions after the per-pixel step (FinishPixelMaps): a map of cluster values that
// HoldUniformClusterMaps kept as a texture stays one (judged again on the pixels, a specular map
// whose clusters were fitted to their own values was filled with its mean after the joint fit); a
// map it held, and a map the pixels refine, are judged on the pixels.
TEST(UniformClusterMaps, TheMapsDecisionAfterThePixelsKeepsTheClustersVerdict) {
  const int specular = static_cast<int>(FitParameter::kSpecular);
  const int roughness = static_cast<int>(FitParameter::kRoughness);
  const int sheen = static_cast<int>(FitParameter::kSheen);
  const int tint = static_cast<int>(FitParameter::kSpecularTint);
  ClusterModel model;  // per pixel: roughness is refined per pixel, specular and sheen are cluster values
  model.clusters = {UniformRuleCluster(0, 0.50, 0.2), UniformRuleCluster(1, 0.52, 0.2)};
  model.measured_any[specular] = model.measured_any[roughness] = model.measured_any[sheen] = true;
  // Sheen was held uniform before the pixels (every cluster fitted with 0.2); specular was not.
  // Specular tint was held too, at 0.3, but cluster 1's pixels hold the default 0, as those of a
  // cluster the model does not explain do (Usable): the held map is then no constant.
  model.uniform_reason[sheen] = "uniform within noise over the clusters (test)";
  model.uniform_reason[tint] = "uniform within noise over the clusters (test)";
  model.measured_any[tint] = true;
  MetricGrid grid;
  grid.width = 4;
  grid.height = 2;
  grid.pitch_mm = 0.1;
  FitResult result = StartPixelMaps(model, grid);
  PixelTally tally;
  tally.cluster_pixels = {4, 4};
  for (int row = 0; row < grid.height; ++row) {
    for (int col = 0; col < grid.width; ++col) {
      const int id = col < 2 ? 0 : 1;
      result.cluster_id.at(0, row, col) = static_cast<float>(id);
      result.parameter_maps[specular].at(0, row, col) = id == 0 ? 0.50f : 0.52f;
      result.parameter_maps[roughness].at(0, row, col) = 0.8f;
      result.parameter_maps[sheen].at(0, row, col) = 0.2f;
      result.parameter_maps[tint].at(0, row, col) = id == 0 ? 0.3f : 0.0f;
    }
  }
  // Spread 0.01 against the clusters' std 0.04: uniform by the pixels' test, a texture by the
  // clusters' verdict.
  FinishPixelMaps(model, tally, &result);
  const MapReport& spec = result.report(FitParameter::kSpecular);
  EXPECT_TRUE(spec.measured);
  EXPECT_FALSE(spec.constant) << spec.reason;
  EXPECT_NEAR(spec.spread, 0.01, 1e-6);
  EXPECT_FLOAT_EQ(result.parameter_maps[specular].at(0, 0, 0), 0.50f) << "the clusters' own values stay";
  EXPECT_FLOAT_EQ(result.parameter_maps[specular].at(0, 1, 3), 0.52f);
  const MapReport& held = result.report(FitParameter::kSheen);
  EXPECT_TRUE(held.constant);
  EXPECT_EQ(held.reason, model.uniform_reason[sheen]);
  EXPECT_FALSE(result.report(FitParameter::kSpecularTint).constant)
      << "held, but half its pixels hold the default: still a texture";
  const MapReport& refined = result.report(FitParameter::kRoughness);
  EXPECT_TRUE(refined.constant) << "refined per pixel: judged on the pixels, which agree";
  EXPECT_NE(refined.reason.find("uniform within noise (spread"), std::string::npos) << refined.reason;
}

// A cluster the model explains grossly badly measures nothing (grazing rig in the stability suite:
// roughness 0.06 for 0.6 was reported measured at relative RMS residuals of 0.18-0.89). Here the
// threshold is lowered to the mismatch flag so that the Charlie-sheen scene crosses it.
TEST_F(PrincipledFitTest, GrossMisfitClusterMeasuresNothing) {
  SceneSpec spec;
  spec.lights_deg = OverheadAndGrazingLights();
  spec.oblique_view = true;
  spec.model = testing::RenderModel::kCharlieSheen;
  spec.material = [&](int col, int row) { return TwoFabrics(col, row, spec.width, true); };
  const Scene scene = MakeScene(spec);
  FitOptions options;
  options.samples_per_cluster = 48;
  options.clustering.cluster_count = 4;
  options.max_iterations = 40;
  options.normal_refinement_max_passes = 0;  // keep the test fast; the rule does not depend on it
  options.unusable_relative_rms = kMismatchFlagRelativeRms;
  const FitResult result = FitPrincipled(scene.stack, scene.geometry, options);
  ExpectFinite(result);
  int misfit_clusters = 0;
  for (const ClusterFit& c : result.clusters) {
    if (!(c.rms_relative_residual > options.unusable_relative_rms)) continue;
    ++misfit_clusters;
    for (int i = 0; i < kFitParameterCount; ++i) {
      EXPECT_FALSE(c.parameters[i].measured) << "cluster " << c.id << " " << FitParameterName(i);
      EXPECT_FALSE(c.parameters[i].reason.empty());
    }
  }
  EXPECT_GT(misfit_clusters, 0) << "the scene must hold a cluster above the threshold";
}

TEST_F(PrincipledFitTest, ModelMismatchIsReported) {
  SceneSpec spec;
  spec.lights_deg = OverheadAndGrazingLights();
  spec.oblique_view = true;
  spec.model = testing::RenderModel::kCharlieSheen;
  spec.material = [&](int col, int row) { return TwoFabrics(col, row, spec.width, true); };
  const Scene scene = MakeScene(spec);
  const std::set<int> held_out = {1, 6, 11, 18};
  FitOptions options;
  options.samples_per_cluster = 48;  // misfit solves iterate long; keep the test fast
  options.clustering.cluster_count = 4;
  options.max_iterations = 40;
  const FitResult result = FitPrincipled(WithoutLights(scene.stack, held_out), scene.geometry, options);
  MaybePrint("ModelMismatchIsReported", result);
  ExpectFinite(result);
  EXPECT_FALSE(result.report(FitParameter::kMetallic).measured) << "a misfit does not make a fabric metallic";
  const double roughness = MeanAbsError(scene, result, FitParameter::kRoughness);
  const double specular = MeanAbsError(scene, result, FitParameter::kSpecular);
  const double sheen = MeanAbsError(scene, result, FitParameter::kSheen);
  double worst_rmse = 0.0;
  for (const Observation& o : scene.stack.observations) {
    if (!held_out.count(o.light)) continue;
    const double rmse = RelativeRmse(RenderFitted(result, scene.stack, scene.geometry, o), o.rgb);
    worst_rmse = std::max(worst_rmse, rmse);
    if (std::getenv("U3MSCAN_FIT_PRINT_JSON") != nullptr) {
      std::cout << "mismatch held-out view " << o.view << " light " << o.light << " rmse " << rmse << "\n";
    }
  }
  double rms_residual = 0.0;
  for (const ClusterFit& c : result.clusters) rms_residual = std::max(rms_residual, c.rms_relative_residual);
  EXPECT_GT(rms_residual, kMismatchFlagRelativeRms) << "the misfit must show in the report";
  bool flagged = false;
  for (const std::string& m : result.convergence.messages) flagged = flagged || m.find("mismatch") != std::string::npos;
  EXPECT_TRUE(flagged) << "the convergence report names the model mismatch";
  ExpectReliabilityVerdicts(scene, result, /*bad_data=*/true);
  bool any_unreliable = false;
  for (const MapReport& m : result.maps) any_unreliable = any_unreliable || (m.measured && !m.reliable);
  EXPECT_TRUE(any_unreliable) << "the misfit clusters' parameters are flagged";
  if (std::getenv("U3MSCAN_FIT_PRINT_JSON") != nullptr) {
    std::cout << "mismatch: mean |error| roughness " << roughness << ", specular " << specular << ", sheen " << sheen
              << " (Charlie sheen value vs Disney sheen fit); worst held-out relative RMSE " << worst_rmse
              << "; worst cluster relative RMS residual " << rms_residual << "\n";
  }
}

// Highlights stretched along y (a twill's warp) are outside the fit's x-axis anisotropy: it fits 0
// at the bound with a small std. The turned-frame test must catch it: the map is not reported as a
// reliable 0 (flagged, or left out naming the y stretch).
// A stretch turned from the fit's x-axis tangent: the twill preset's anisotropic 0.2 with fibres
// at `turn_deg` from world +x (90: a warp along y, a probe angle; 30 and 120: between the probes,
// found by the parabola step), one cluster, noise-free.
// One stretched material (roughness 0.5, specular 0.5) on the overhead rig with fibres at
// `tangent_deg` per pixel, noise-free.
Scene StretchedScene(double anisotropic, std::function<double(int col, int row)> tangent_deg) {
  SceneSpec spec;
  spec.lights_deg = OverheadLights();
  spec.material = [anisotropic](int, int) {
    PrincipledParams<double> p;
    p.base_color = Eigen::Vector3d(0.45, 0.36, 0.22);
    p.roughness = 0.5;
    p.specular = 0.5;
    p.anisotropic = anisotropic;
    return p;
  };
  spec.tangent_deg = std::move(tangent_deg);
  return MakeScene(spec);
}

Scene TurnedStretchScene(double turn_deg) {
  return StretchedScene(0.2, [turn_deg](int, int) { return turn_deg; });  // the twill preset's stretch
}

// Angle between two stretch directions (degrees, the stretch repeats every 180).
double StretchAngleBetween(double a_deg, double b_deg) {
  const double d = std::fmod(std::abs(a_deg - b_deg), 180.0);
  return std::min(d, 180.0 - d);
}

// The search (cost scan every 15 degrees, then parabolas 3 degrees wide with solves) on noise-free
// data: measured 0.020 / 0.027 / 0.016 degrees off for 90 / 30 / 120 (docs/fitting.md
// "Anisotropy"); the refinement stops once the turn moves less than 0.1 degree.
constexpr double kRotationToleranceDeg = 0.5;
// anisotropic at that angle: within the exact-recovery tolerance of the truth.
constexpr double kTurnedStretchTolerance = kExactParameterTolerance;

class TurnedStretch : public ::testing::TestWithParam<double> {
 protected:
  void SetUp() override { SetLogLevel(LogLevel::kWarning); }
};

TEST_P(TurnedStretch, RotationAndStretchAreRecoveredAndReRender) {
  const double turn_deg = GetParam();
  const Scene scene = TurnedStretchScene(turn_deg);
  const std::set<int> held_out = {3, 9};
  FitOptions options;
  options.clustering.cluster_count = 1;
  const FitResult result = FitPrincipled(WithoutLights(scene.stack, held_out), scene.geometry, options);
  ExpectFinite(result);
  ASSERT_EQ(result.clusters.size(), 1u);
  const MapReport& stretch = result.report(FitParameter::kAnisotropic);
  ASSERT_TRUE(stretch.measured) << stretch.reason;
  EXPECT_NEAR(stretch.value, 0.2, kTurnedStretchTolerance);
  const MapReport& turn = result.rotation_report;
  ASSERT_TRUE(turn.measured) << turn.reason;
  EXPECT_TRUE(turn.constant) << "one cluster, one turn";
  EXPECT_TRUE(result.anisotropy_rotation_deg.empty()) << "a constant turn has no image";
  EXPECT_LT(StretchAngleBetween(turn.value, turn_deg), kRotationToleranceDeg) << "fitted " << turn.value;
  EXPECT_EQ(result.clusters[0].anisotropy_rotation_deg, turn.value);
  // RenderFitted shades in the turned frame: held-out lights re-render within the issue's 2 %.
  for (const Observation& o : scene.stack.observations) {
    if (!held_out.count(o.light)) continue;
    EXPECT_LT(RelativeRmse(RenderFitted(result, scene.stack, scene.geometry, o), o.rgb), kHeldOutRelativeRmse)
        << "light " << o.light;
  }
  EXPECT_TRUE(pipeline::FitResultToJson(result)["clusters"][0]["anisotropy_rotation_deg"].is_number());
}

INSTANTIATE_TEST_SUITE_P(Turns, TurnedStretch, ::testing::Values(90.0, 30.0, 120.0));

TEST_F(PrincipledFitTest, StretchAlongTheTangentKeepsTurnZero) {
  // The fit's own tangent (fibres along x): no turn is adopted, and the rotation is a measured 0.
  const Scene scene = TurnedStretchScene(0.0);
  FitOptions options;
  options.clustering.cluster_count = 1;
  const FitResult result = FitPrincipled(scene.stack, scene.geometry, options);
  ASSERT_TRUE(result.report(FitParameter::kAnisotropic).measured);
  EXPECT_NEAR(result.report(FitParameter::kAnisotropic).value, 0.2, kExactParameterTolerance);
  EXPECT_TRUE(result.rotation_report.measured);
  EXPECT_EQ(result.rotation_report.value, 0.0);
  EXPECT_EQ(result.clusters[0].anisotropy_rotation_deg, 0.0);
}

// Fibres that change direction across one cluster (a lace's cord round its motif): the left half
// at 30 degrees, the right half at 120, one material (anisotropic 0.3), noise-free.
Scene TwoFibreDirectionsScene() {
  return StretchedScene(0.3, [width = SceneSpec().width](int col, int) { return col < width / 2 ? 30.0 : 120.0; });
}

TEST_F(PrincipledFitTest, PixelTurnsLetOneClusterFollowFibresThatChangeDirection) {
  Scene scene = TwoFibreDirectionsScene();
  const std::set<int> held_out = {3, 9};
  const Stack fitted_lights = WithoutLights(scene.stack, held_out);
  FitOptions options;
  options.clustering.cluster_count = 1;
  // Without the pixels' turns one turn cannot serve both halves: the stretch is not recovered.
  const FitResult one_turn = FitPrincipled(fitted_lights, scene.geometry, options);
  ExpectFinite(one_turn);
  const MapReport& one_turn_stretch = one_turn.report(FitParameter::kAnisotropic);
  EXPECT_FALSE(one_turn_stretch.measured && std::abs(one_turn_stretch.value - 0.3) < kExactParameterTolerance)
      << "one turn recovered both directions' stretch: the test would not show the pixels' turns";

  // With them (the render's own directions, as pipeline/fibre_direction.h reads them from a relief).
  scene.geometry.fibre_turn_deg = Image(scene.stack.grid.width, scene.stack.grid.height, 1, 0.0f, scene.stack.grid.pitch_mm);
  for (int row = 0; row < scene.stack.grid.height; ++row) {
    for (int col = 0; col < scene.stack.grid.width; ++col) {
      scene.geometry.fibre_turn_deg.at(0, row, col) = col < scene.stack.grid.width / 2 ? 30.0f : 120.0f;
    }
  }
  const FitResult result = FitPrincipled(fitted_lights, scene.geometry, options);
  ExpectFinite(result);
  ASSERT_EQ(result.clusters.size(), 1u);
  const MapReport& stretch = result.report(FitParameter::kAnisotropic);
  ASSERT_TRUE(stretch.measured) << stretch.reason;
  EXPECT_NEAR(stretch.value, 0.3, kExactParameterTolerance);
  EXPECT_LT(StretchAngleBetween(result.clusters[0].anisotropy_rotation_deg, 0.0), kRotationToleranceDeg)
      << "the cluster's own turn on top of the pixels' should be none";
  // The rotation is a texture: each pixel's turn.
  ASSERT_TRUE(result.rotation_report.measured) << result.rotation_report.reason;
  EXPECT_FALSE(result.rotation_report.constant);
  ASSERT_FALSE(result.anisotropy_rotation_deg.empty());
  for (int row = 0; row < scene.stack.grid.height; ++row) {
    for (int col = 0; col < scene.stack.grid.width; ++col) {
      const double expected = col < scene.stack.grid.width / 2 ? 30.0 : 120.0;
      EXPECT_LT(StretchAngleBetween(result.anisotropy_rotation_deg.at(0, row, col), expected), kRotationToleranceDeg)
          << "pixel " << col << ", " << row;
    }
  }
  // RenderFitted shades with the rotation map: held-out lights re-render within the issue's 2 %.
  for (const Observation& o : scene.stack.observations) {
    if (!held_out.count(o.light)) continue;
    EXPECT_LT(RelativeRmse(RenderFitted(result, scene.stack, scene.geometry, o), o.rgb), kHeldOutRelativeRmse)
        << "light " << o.light;
  }
}

TEST_F(PrincipledFitTest, PixelTurnsOfTheWrongSizeAreRefused) {
  Scene scene = TwoFibreDirectionsScene();
  scene.geometry.fibre_turn_deg = Image(3, 3, 1, 0.0f, scene.stack.grid.pitch_mm);
  EXPECT_THROW(FitPrincipled(scene.stack, scene.geometry, FitOptions()), std::invalid_argument);
}

TEST_F(PrincipledFitTest, WithoutTheRotationSearchAStretchAlongYIsNotReportedAsReliableZero) {
  const Scene scene = TurnedStretchScene(90.0);
  FitOptions options;
  options.clustering.cluster_count = 1;
  options.fit_anisotropy_rotation = false;
  const FitResult result = FitPrincipled(scene.stack, scene.geometry, options);
  ExpectFinite(result);
  EXPECT_FALSE(result.rotation_report.measured);
  EXPECT_EQ(result.clusters[0].anisotropy_rotation_deg, 0.0);
  const MapReport& a = result.report(FitParameter::kAnisotropic);
  if (a.measured) {
    EXPECT_FALSE(a.reliable) << "anisotropic " << a.value << " reported reliable for a stretch along y";
    EXPECT_NE(a.unreliable_reason.find("image y axis"), std::string::npos) << a.unreliable_reason;
  } else {
    EXPECT_NE(a.reason.find("image y axis"), std::string::npos) << a.reason;
  }
}

// Measurement, not a correctness test (docs/fitting.md, "Anisotropy: what the rig can observe"):
// the posterior std and fitted value of anisotropic 0.2 (the twill preset's) on the overhead rig,
// noise-free, one cluster, for roughness 0.3 / 0.5 / 0.7 and fibres along the fit's tangent (0 deg),
// across it (90 deg, a twill's warp when the weft runs along x) and half and half. Run explicitly:
//   fitting_tests --gtest_also_run_disabled_tests --gtest_filter='*DISABLED_AnisotropyObservability*'
TEST_F(PrincipledFitTest, DISABLED_AnisotropyObservability) {
  for (double roughness : {0.3, 0.5, 0.7}) {
    for (int layout = 0; layout < 3; ++layout) {
      SceneSpec spec;
      spec.lights_deg = OverheadLights();
      spec.material = [roughness](int, int) {
        PrincipledParams<double> p;
        p.base_color = Eigen::Vector3d(0.45, 0.36, 0.22);
        p.roughness = roughness;
        p.specular = 0.5;
        p.anisotropic = 0.2;
        return p;
      };
      spec.tangent_deg = [layout](int col, int) { return layout == 0 ? 0.0 : layout == 1 ? 90.0 : (col % 2) * 90.0; };
      const Scene scene = MakeScene(spec);
      FitOptions options;
      options.clustering.cluster_count = 1;
      options.observability.max_std = 1.0;  // report the value and std whatever they are
      const FitResult result = FitPrincipled(scene.stack, scene.geometry, options);
      const ParameterEstimate& a = result.clusters[0].parameters[static_cast<int>(FitParameter::kAnisotropic)];
      const ParameterEstimate& r = result.clusters[0].parameters[static_cast<int>(FitParameter::kRoughness)];
      std::cout << "roughness " << roughness << ", fibres " << (layout == 0 ? "along x" : layout == 1 ? "along y" : "x|y alternating")
                << ": anisotropic " << a.value << " std " << a.std_dev << (a.measured ? "" : " (left out)")
                << ", roughness " << r.value << ", relative RMS residual " << result.clusters[0].rms_relative_residual
                << (a.reliable ? "" : ", flagged: " + a.unreliable_reason) << (a.measured ? "" : ", " + a.reason) << "\n";
      EXPECT_TRUE(std::isfinite(a.value));
    }
  }
}

// Throughput check, not a correctness test (no test asserts time): a 512 x 512 grid (0.26 MP)
// with the overhead rig (16 observations; U3MSCAN_FIT_OBLIQUE=1: oblique rig, 40), default options.
// Run explicitly:
//   fitting_tests --gtest_also_run_disabled_tests --gtest_filter='*DISABLED_Throughput*'
// and scale the per-pixel time linearly to 36 MP (cluster fits do not grow with the image).
TEST_F(PrincipledFitTest, DISABLED_Throughput) {
  SceneSpec spec;
  spec.width = 512;
  spec.height = 512;
  spec.pitch_mm = 0.02;
  spec.lights_deg = OverheadLights();
  if (std::getenv("U3MSCAN_FIT_OBLIQUE") != nullptr) {  // 20 lights x 2 views = 40 observations
    for (const auto& l : GrazingLights()) spec.lights_deg.push_back(l);
    spec.oblique_view = true;
  }
  spec.material = [&](int col, int row) { return TwoFabrics(col / 8, row / 8, spec.width / 8, false); };
  const Scene scene = MakeScene(spec);
  FitOptions options;
  if (std::getenv("U3MSCAN_FIT_NO_REFINE") != nullptr) options.mode = FitMode::kClusters;
  const FitResult result = FitPrincipled(scene.stack, scene.geometry, options);
  const double megapixels = spec.width * spec.height / 1e6;
  std::cout << "pixels " << spec.width * spec.height << ", observations " << scene.stack.observations.size()
            << ", clusters " << result.clusters.size() << ", refined " << result.convergence.pixels_refined << "\n"
            << "gather " << result.times.gather_s << " s, clustering " << result.times.clustering_s
            << " s, cluster fit " << result.times.cluster_fit_s << " s, per pixel " << result.times.per_pixel_s
            << " s (" << result.times.per_pixel_s / megapixels << " s/MP), total " << result.times.total_s << " s\n";
  ExpectFinite(result);
}

}  // namespace

}  // namespace u3mscan::fitting
