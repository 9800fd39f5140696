// End to end against the truth (issue 7): the bump field of tests/support/bump_scene.h rendered by
// the synthetic scanner WITH the rig's sensor noise, processed by ProcessCapture (the `process`
// command's code path, default preset) and compared with bench::Evaluate (`u3mscan evaluate`) to
// the scene's truth. Every figure is held to the target of the issue it belongs to (issue 5:
// reconstruction, issue 6: fitting); distant and near rigs, with the radiometric calibration frames
// only and with every calibration frame (the mirror spheres, board and chart too).
#include <gtest/gtest.h>

#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <string>

#include "bench/evaluate.h"
#include "datasets_synthetic/capture_writer.h"
#include "datasets_synthetic/rig.h"
#include "core/error.h"
#include "pipeline/process.h"
#include "tests/support/bump_scene.h"
#include "u3m/image_io.h"

namespace u3mscan {
namespace {

namespace fs = std::filesystem;

constexpr int kCameraPixels = 64;
constexpr int kScenePixels = 56;
constexpr double kBumpAmplitudeMm = 0.05;
constexpr double kBumpPeriodMm = 1.5;
// Issue 6 (fitting) targets: absolute errors of the fitted parameters, and the relative RMSE of a
// re-render under lights left out of the fit.
constexpr double kRoughnessTolerance = 0.05;
constexpr double kSpecularTolerance = 0.1;
constexpr double kRerenderTolerance = 0.02;
// Issue 5 (reconstruction) targets: base colour CIEDE2000, mean normal angular error on a
// Lambertian-dominant surface (this lobe carries ~10 % of the signal at its peak), height RMSE in
// % of the truth's range.
constexpr double kBaseColorDeltaE = 1.5;
constexpr double kNormalMeanDeg = 1.0;
constexpr double kHeightRmsePercent = 2.0;
// The bump scene ends exactly at the grid's edge, so the camera pixels of the outermost rows and
// columns integrate part of the table beyond it (near rig, before this border was left out: base
// colour 0.39 for 0.6 in the last column, re-render error 28-35 % there, 5.6 % over the grid).
// That is the synthetic scene, not the chain: these pixels are marked "not fabric" in the truth's
// alpha so that Evaluate leaves them out (the same border as the data check of
// tests/fitting/end_to_end_accuracy_test.cc).
constexpr int kBorderPixels = 4;

void LeaveBorderOutOfComparison(const fs::path& truth_dir) {
  const fs::path path = truth_dir / "alpha.exr";
  Image alpha = ReadImageFile(path, PixelEncoding::kLinear);
  for (int row = 0; row < alpha.height(); ++row) {
    for (int col = 0; col < alpha.width(); ++col) {
      const bool border = row < kBorderPixels || col < kBorderPixels || row >= alpha.height() - kBorderPixels ||
                          col >= alpha.width() - kBorderPixels;
      if (border) alpha.at(0, row, col) = 0.0f;
    }
  }
  ImageWriteOptions options;
  options.format = SampleFormat::kFloat32;
  WriteImageFile(alpha, path, options);
}

// The scanner's calibration frames: only its radiometric ones (dark, a flat per light; geometry and
// colour from the manifest, so the errors are the chain's own), or every one (the lights from the
// mirror spheres, the pose from the board, colour from the chart: the whole calibration chain).
struct TruthCase {
  const char* rig;
  bool all_calibration_frames;
};

std::string CaseName(const TruthCase& c) {
  return std::string(c.rig) + (c.all_calibration_frames ? "_all_calibration" : "_dark_and_flats");
}

class ProcessTruth : public ::testing::TestWithParam<TruthCase> {
 protected:
  void SetUp() override {
    root_ = fs::temp_directory_path() / ("u3mscan_process_truth_" + CaseName(GetParam()) + "_" +
                                         std::to_string(::getpid()));
    fs::remove_all(root_);
    synthetic::RigOptions rig_options;
    rig_options.width = kCameraPixels;
    rig_options.height = kCameraPixels;
    const synthetic::Rig rig = synthetic::MakeRig(GetParam().rig, rig_options);  // the rig's sensor noise
    const auto scene = testing::BumpScene(kScenePixels, kScenePixels, rig_options.pitch_mm, kBumpAmplitudeMm,
                                          kBumpPeriodMm);
    synthetic::CaptureOptions capture_options;
    capture_options.format = synthetic::FrameFormat::kTiff;
    // Flat fields in both cases: without them the near rig's lens vignetting (-12 % r^2 of the half
    // diagonal, measurable only by a flat frame) took the held-out re-render to 2.52 %.
    if (!GetParam().all_calibration_frames) capture_options.calibration_roles = {FrameRole::kDark, FrameRole::kFlat};
    synthetic::WriteSyntheticCapture(scene, rig, capture_options, root_ / "bumps");
    LeaveBorderOutOfComparison(root_ / "bumps" / synthetic::kTruthSubdir);
  }
  void TearDown() override {
    if (!std::getenv("U3MSCAN_KEEP_TEST_OUTPUT")) fs::remove_all(root_);
  }
  fs::path root_;
};

TEST_P(ProcessTruth, MapsMatchTheTruthWithinTheIssueTargets) {
  const CaptureJob job{root_ / "bumps" / synthetic::kCaptureSubdir, root_ / "out", "bumps"};
  ProcessOptions options;  // default preset
  options.debug_maps = true;  // maps/*.exr for the evaluation
  ProcessCapture(job, options);
  const bench::Evaluation e = bench::Evaluate(job.out_dir, root_ / "bumps" / synthetic::kTruthSubdir);
  std::cout << "[ MEASURED ] " << CaseName(GetParam()) << "\n" << bench::EvaluationToText(e);

  ASSERT_GT(e.pixels_compared, 0);
  EXPECT_LT(e.normal_mean_deg, kNormalMeanDeg);
  EXPECT_LT(e.base_color_de_mean, kBaseColorDeltaE);
  EXPECT_LT(e.height_rmse_percent, kHeightRmsePercent);
  const bench::ParameterError& roughness = bench::FindParameter(e, "roughness");
  const bench::ParameterError& specular = bench::FindParameter(e, "specular");
  ASSERT_TRUE(roughness.measured);
  ASSERT_TRUE(specular.measured);
  EXPECT_TRUE(roughness.reliable);
  EXPECT_TRUE(specular.reliable);
  EXPECT_LT(roughness.mean_abs_error, kRoughnessTolerance);
  EXPECT_LT(specular.mean_abs_error, kSpecularTolerance);
  // Sheen (truth 0) cannot be measured from an overhead camera: it must be left out, not reported.
  EXPECT_FALSE(bench::FindParameter(e, "sheen").measured);
  ASSERT_GT(e.held_out_lights, 0);
  EXPECT_LT(e.rerender_relative_rmse, kRerenderTolerance);
}

// The issue's "re-rendered images of lights left out of the fit", against the photographs
// themselves: `--hold-out-lights` keeps two of the rig's lights out of reconstruction and fit, and
// the report gives the fitted material's error under them (the frames' sensor noise included).
TEST_P(ProcessTruth, HeldOutPhotographsReRenderWithinTheIssueTarget) {
  const CaptureJob job{root_ / "bumps" / synthetic::kCaptureSubdir, root_ / "held_out", "bumps"};
  ProcessOptions options;
  options.hold_out_lights = {"L02", "L05"};
  const ProcessResult result = ProcessCapture(job, options);
  const nlohmann::json& held = result.report.quality["front"]["held_out_lights"];
  ASSERT_TRUE(held.is_object()) << result.report.quality.dump();
  ASSERT_EQ(held["lights"].size(), 2u);
  for (const nlohmann::json& light : held["lights"]) {
    EXPECT_GT(light["pixels"].get<std::size_t>(), 0u) << light.dump();
    EXPECT_LT(light["relative_rmse"].get<double>(), kRerenderTolerance) << light.dump();
  }
  const double pooled = held["relative_rmse"].get<double>();
  std::cout << "[ MEASURED ] " << CaseName(GetParam()) << ": held-out photographs re-render relative RMSE "
            << 100.0 * pooled << " %\n";
  EXPECT_LT(pooled, kRerenderTolerance);
  EXPECT_EQ(result.report.options["hold_out_lights"], nlohmann::json::array({"L02", "L05"}));

  // A light the capture does not have, or too few lights left (14 of the rig's 16 held out):
  // refused, naming the option, and nothing written.
  std::vector<std::string> all_but_two;
  for (int k = 0; k < 14; ++k) all_but_two.push_back((k < 10 ? "L0" : "L") + std::to_string(k));
  for (const std::vector<std::string>& ids : {std::vector<std::string>{"L99"}, all_but_two}) {
    const CaptureJob refused{job.capture_dir, root_ / "refused", "bumps"};
    options.hold_out_lights = ids;
    try {
      ProcessCapture(refused, options);
      ADD_FAILURE() << "holding out " << ids.front() << "... was accepted";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("--hold-out-lights"), std::string::npos) << e.what();
    }
    EXPECT_FALSE(fs::exists(refused.out_dir)) << "a refused run wrote " << refused.out_dir;
  }
}

INSTANTIATE_TEST_SUITE_P(Rigs, ProcessTruth,
                         ::testing::Values(TruthCase{"distant", false}, TruthCase{"near", false},
                                           TruthCase{"distant", true}, TruthCase{"near", true}),
                         [](const ::testing::TestParamInfo<TruthCase>& info) { return CaseName(info.param); });

}  // namespace
}  // namespace u3mscan
