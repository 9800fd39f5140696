// End-to-end accuracy of the fit (issue 6 targets) on a tiny noise-free synthetic capture: the
// bump field of tests/support/bump_scene.h on the `distant` and `near` rigs, written by the
// synthetic scanner, calibrated, rectified, reconstructed (photometric stereo) and fitted by the
// pipeline's stages at the default preset.
//
// Regression test of the normal refinement in FitPrincipled (docs/fitting.md): with the
// photometric-stereo normals as they are (normal_refinement_max_passes = 0) specular 0.5 came out 0.23
// and roughness 0.6 came out 0.54; each Stack observation matched the core BRDF evaluated with the
// true normal, light and view to 0.05 %, so the loss was the Lambertian normals' ~1 deg lean.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include <unistd.h>

#include <Eigen/Geometry>

#include "core/principled_brdf.h"
#include "datasets_synthetic/capture_writer.h"
#include "datasets_synthetic/rig.h"
#include "pipeline/stages.h"
#include "tests/support/bump_scene.h"

namespace u3mscan {
namespace {
namespace fs = std::filesystem;

constexpr int kCameraPixels = 32;
constexpr int kScenePixels = 28;
constexpr double kPitchMm = 25.4 / 300.0;
constexpr double kBumpAmplitudeMm = 0.05;
constexpr double kBumpPeriodMm = 1.5;
constexpr double kTruthRoughness = 0.6;  // BumpScene's uniform parameters
constexpr double kTruthSpecular = 0.5;
// Issue 6 accuracy targets.
constexpr double kRoughnessTarget = 0.05;
constexpr double kSpecularTarget = 0.1;
constexpr double kRerenderTarget = 0.02;  // relative RMSE of a re-render under lights left out of the fit
constexpr int kHeldOutEvery = 4;          // every 4th light (4 of 16) is left out of reconstruction and fit
// The synthetic frames against the core BRDF with the true normal (rectification, irradiance,
// light and view vectors): mean relative error of an observation over the inner pixels.
constexpr double kDataModelTolerance = 0.005;
constexpr int kBorderPixels = 4;  // rectification's edge pixels are left out of the data check

class EndToEndAccuracy : public ::testing::TestWithParam<const char*> {
 protected:
  void SetUp() override {
    root_ = fs::temp_directory_path() / ("u3mscan_accuracy_" + std::string(GetParam()) + "_" + std::to_string(::getpid()));
    fs::remove_all(root_);
    scene_ = testing::BumpScene(kScenePixels, kScenePixels, kPitchMm, kBumpAmplitudeMm, kBumpPeriodMm);
    synthetic::RigOptions rig_options;
    rig_options.width = kCameraPixels;
    rig_options.height = kCameraPixels;
    rig_ = synthetic::MakeRig(GetParam(), rig_options);
    // Noise-free sensor: no read noise, no fixed pattern, shot noise negligible.
    rig_.sensor.read_noise_e = 0.0;
    rig_.sensor.fixed_pattern_dn = 0.0;
    rig_.sensor.full_well_e = 1e12;
    synthetic::CaptureOptions capture_options;
    capture_options.format = synthetic::FrameFormat::kTiff;
    // The scanner's radiometric calibration only: dark and one flat field per light (the near rig's
    // lens vignetting is in them); geometry and colour from the manifest, so that the errors measured
    // are the chain's own.
    capture_options.calibration_roles = {FrameRole::kDark, FrameRole::kFlat};
    synthetic::WriteSyntheticCapture(scene_, rig_, capture_options, root_ / "synthetic");
    options_ = OptionsForPreset(Preset::kBalanced);  // the default preset
    prepared_ = std::make_unique<PreparedCapture>(
        PrepareCapture(root_ / "synthetic" / synthetic::kCaptureSubdir, options_, &report_));
    stack_ = BuildSideStack(*prepared_, "front", options_, &report_);
  }
  void TearDown() override { fs::remove_all(root_); }

  fitting::FitResult Fit(const StageOptions& options) {
    const Image alpha(stack_.grid.width, stack_.grid.height, 1, 1.0f, stack_.grid.pitch_mm);
    const SideReconstruction geometry = ReconstructSide(&stack_, options, alpha, &report_);
    return FitSide(stack_, geometry, options, &report_);
  }

  fs::path root_;
  synthetic::SceneTruth scene_;
  synthetic::Rig rig_;
  StageOptions options_;
  RunReport report_;
  std::unique_ptr<PreparedCapture> prepared_;
  Stack stack_;
};

// The data side: every Stack observation equals the core BRDF with the true normal, parameters,
// light and view (the grid and the scene share pixel centres and pitch), with the irradiance the
// flat frames measured. Without the flats the near rig's observations came out 1.47 % darker than
// the model (RMS 1.8 %, the same for every light): its lens vignetting (polynomial, -12 % r^2 of the
// half diagonal), which only a flat frame measures; rendered with vignetting off they matched to
// 0.05 %, and with the flats they do too (measured 0.03-0.05 %). Upstream of the fit.
TEST_P(EndToEndAccuracy, StackMatchesTheBrdfWithTrueGeometry) {
  ASSERT_EQ(stack_.grid.width, kScenePixels);
  PrincipledParams<double> truth;
  truth.base_color = Vec3<double>(0.6, 0.4, 0.3);
  truth.roughness = kTruthRoughness;
  truth.specular = kTruthSpecular;
  for (const Observation& o : stack_.observations) {
    const LightModel& light = stack_.lights[o.light];
    const Eigen::Vector3d camera = stack_.views[o.view].centre_in_world_mm;
    double sum = 0.0, sum2 = 0.0;
    int count = 0;
    for (int row = kBorderPixels; row < kScenePixels - kBorderPixels; ++row) {
      for (int col = kBorderPixels; col < kScenePixels - kBorderPixels; ++col) {
        const Eigen::Vector3d x = stack_.grid.PixelCentreInWorld(col, row, scene_.height_mm.at(0, row, col));
        const Eigen::Vector3d n(scene_.normal.at(0, row, col), scene_.normal.at(1, row, col), scene_.normal.at(2, row, col));
        const Eigen::Vector3d t = (Eigen::Vector3d::UnitX() - n.x() * n).normalized();
        const Eigen::Vector3d b = n.cross(t);
        const Eigen::Vector3d lw = light.DirectionFrom(x), vw = (camera - x).normalized();
        const Vec3<double> l(lw.dot(t), lw.dot(b), lw.dot(n)), v(vw.dot(t), vw.dot(b), vw.dot(n));
        const double e = o.irradiance.empty() ? light.RelativeIrradianceAt(x) : o.irradiance.at(0, row, col);
        for (int c = 0; c < 3; ++c) {
          const double model = EvaluatePrincipled(truth, l, v)(c) * l.z() * e;
          sum += o.rgb.at(c, row, col) / model - 1.0;
          sum2 += (o.rgb.at(c, row, col) / model - 1.0) * (o.rgb.at(c, row, col) / model - 1.0);
          ++count;
        }
      }
    }
    std::cout << "[ MEASURED ] light " << light.id << " mean relative error " << sum / count << " rms " << std::sqrt(sum2 / count) << "\n";
    EXPECT_LT(std::abs(sum / count), kDataModelTolerance) << "light " << light.id;
  }
}

// The report's re-render residual map is bounded per pixel: an observation whose data is noise
// about zero (a shadowed gap) must not dominate the mean (|r - d| / d read 31781 on such a pixel).
constexpr double kResidualOfAgreeingPixels = 0.02;  // measured 0.015 over the whole bump grid, border included
TEST_P(EndToEndAccuracy, ReRenderResidualMapIsBoundedWhereTheDataIsNearZero) {
  const Image alpha(stack_.grid.width, stack_.grid.height, 1, 1.0f, stack_.grid.pitch_mm);
  const SideReconstruction geometry = ReconstructSide(&stack_, options_, alpha, &report_);
  const fitting::FitResult fit = FitSide(stack_, geometry, options_, &report_);
  const int row = kScenePixels / 2, col = kScenePixels / 2;
  for (Observation& o : stack_.observations) {
    for (int c = 0; c < 3; ++c) o.rgb.at(c, row, col) = 1e-9f;  // data = noise about zero
  }
  double mean = 0.0;
  const Image residual = FitResidualMap(fit, stack_, geometry, static_cast<int>(stack_.observations.size()), &mean);
  float largest = 0.0f;
  for (float v : residual.plane(0)) largest = std::max(largest, v);
  std::cout << "[ MEASURED ] residual map: mean " << mean << ", largest " << largest << " (the near-zero pixel "
            << residual.at(0, row, col) << ")\n";
  EXPECT_LE(largest, 2.0f);
  EXPECT_GT(residual.at(0, row, col), 1.0f);  // that pixel is still reported as not matching
  // One pixel of 784 at <= 2: the mean stays that of the agreeing pixels.
  EXPECT_LT(mean, kResidualOfAgreeingPixels + 2.0 / (kScenePixels * kScenePixels));
}

// The fit side: specular and roughness within the issue-6 targets through the whole chain.
TEST_P(EndToEndAccuracy, SpecularAndRoughnessWithinIssue6Targets) {
  const fitting::FitResult fit = Fit(options_);
  const auto& roughness = fit.report(fitting::FitParameter::kRoughness);
  const auto& specular = fit.report(fitting::FitParameter::kSpecular);
  std::cout << "[ MEASURED ] roughness " << roughness.value << " (truth " << kTruthRoughness << "), specular "
            << specular.value << " (truth " << kTruthSpecular << ")\n";
  ASSERT_TRUE(roughness.measured) << roughness.reason;
  ASSERT_TRUE(specular.measured) << specular.reason;
  EXPECT_NEAR(roughness.value, kTruthRoughness, kRoughnessTarget);
  EXPECT_NEAR(specular.value, kTruthSpecular, kSpecularTarget);
}

// Lights left out of reconstruction and fit, re-rendered from the fitted maps with the fit's
// refined normals and the height integrated from them (what `process` writes), against their data.
TEST_P(EndToEndAccuracy, LeftOutLightsReRenderWithinIssue6Target) {
  Stack fitted = stack_;
  fitted.observations.clear();
  std::vector<Observation> held_out;
  for (std::size_t k = 0; k < stack_.observations.size(); ++k) {
    (k % kHeldOutEvery == 1 ? held_out : fitted.observations).push_back(stack_.observations[k]);
  }
  const Image alpha(fitted.grid.width, fitted.grid.height, 1, 1.0f, fitted.grid.pitch_mm);
  SideReconstruction geometry = ReconstructSide(&fitted, options_, alpha, &report_);
  fitting::FitResult fit = FitSide(fitted, geometry, options_, &report_);
  const bool near = std::string(GetParam()) == "near";
  ASSERT_TRUE(AdoptFittedNormals(&fit, fitted.grid, near, options_, &geometry, &report_));
  const fitting::SurfaceGeometry surface{geometry.photometric_stereo.normal, geometry.photometric_stereo.albedo,
                                         geometry.height_mm, Image(), Image(), 1};
  double num = 0.0, den = 0.0;
  for (const Observation& o : held_out) {
    const Image render = fitting::RenderFitted(fit, fitted, surface, o);
    for (int row = kBorderPixels; row < kScenePixels - kBorderPixels; ++row) {
      for (int col = kBorderPixels; col < kScenePixels - kBorderPixels; ++col) {
        if (!o.flags.empty() && o.flags[static_cast<std::size_t>(row) * kScenePixels + col] != 0) continue;
        for (int c = 0; c < 3; ++c) {
          const double d = o.rgb.at(c, row, col), r = render.at(c, row, col);
          num += (r - d) * (r - d);
          den += d * d;
        }
      }
    }
  }
  ASSERT_GT(den, 0.0);
  const double rmse = std::sqrt(num / den);
  std::cout << "[ MEASURED ] " << GetParam() << ": left-out lights re-render relative RMSE " << 100.0 * rmse << " %\n";
  EXPECT_LT(rmse, kRerenderTarget);
}

// Without the normal refinement the Lambertian normals bias specular low: the refinement is what
// brings it within the target (guards against the refinement being silently disabled or broken).
TEST_P(EndToEndAccuracy, NormalRefinementRemovesTheSpecularBias) {
  StageOptions without = options_;
  without.fit.normal_refinement_max_passes = 0;
  const double biased = Fit(without).report(fitting::FitParameter::kSpecular).value;
  const double refined = Fit(options_).report(fitting::FitParameter::kSpecular).value;
  std::cout << "[ MEASURED ] specular without normal refinement " << biased << ", with " << refined << "\n";
  EXPECT_GT(std::abs(biased - kTruthSpecular), kSpecularTarget);
  EXPECT_LT(std::abs(refined - kTruthSpecular), std::abs(biased - kTruthSpecular));
}

INSTANTIATE_TEST_SUITE_P(Rigs, EndToEndAccuracy, ::testing::Values("distant", "near"));

}  // namespace
}  // namespace u3mscan
