// The chain's accuracy against issue 5's targets: a small synthetic capture (supersampled renders,
// area-average truth, the rig's sensor noise, 16-bit TIFF) -> the pipeline's stages (manifest
// poses and lights, rectification, photometric stereo, integration) -> normal, albedo and height,
// compared with the truth on the same grid. Asserted only where the chain meets the targets:
// the smooth, Lambertian-like `bumps` preset on the distant and near rigs. The fabric presets do
// not meet them yet (docs/reconstruction.md, "Chain accuracy"): not asserted here, reported there.
#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <numbers>
#include <string>

#include "core/colour.h"
#include "core/logging.h"
#include "datasets_synthetic/rig.h"
#include "datasets_synthetic/synth_run.h"
#include "pipeline/presets.h"
#include "pipeline/stages.h"

namespace u3mscan {
namespace {

namespace fs = std::filesystem;

// Issue 5's targets for Lambertian-dominant surfaces.
constexpr double kNormalTargetDeg = 1.0;
constexpr double kAlbedoTargetDe = 1.5;          // CIEDE2000
constexpr double kHeightTargetPercent = 2.0;     // RMSE after removing the mean offset, % of range
constexpr int kCameraPixels = 96;                // 72 x 72 output pixels at 300 dpi

struct ChainErrors {
  double normal_deg = 0, albedo_de = 0, height_percent = 0;
};

ChainErrors RunChain(const std::string& rig_name) {
  const fs::path dir = fs::temp_directory_path() / ("u3mscan_chain_accuracy_" + rig_name + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  synthetic::RigOptions rig_options;
  rig_options.width = rig_options.height = kCameraPixels;
  const synthetic::Rig rig = synthetic::MakeRig(rig_name, rig_options);
  synthetic::SceneOptions grid;
  grid.width = grid.height = static_cast<int>(std::lround(synthetic::kSampleFillOfView * kCameraPixels));
  grid.pitch_mm = rig_options.pitch_mm;
  const int supersample = synthetic::AutoSupersample(kCameraPixels, kCameraPixels);
  const synthetic::OversampledScene scene = synthetic::MakeOversampledScene("bumps", grid, supersample);
  synthetic::CaptureOptions capture;
  capture.format = synthetic::FrameFormat::kTiff;
  capture.calibration_frames = false;
  capture.supersample = supersample;
  synthetic::WriteSyntheticCapture(scene.fine, scene.truth, rig, capture, dir);

  StageOptions stages = OptionsForPreset(Preset::kBalanced);
  RunReport report;
  PreparedCapture prepared = PrepareCapture(dir / synthetic::kCaptureSubdir, stages, &report);
  Stack stack = BuildSideStack(prepared, "front", stages, &report);
  const SideReconstruction rec = ReconstructSide(&stack, stages, Image(), &report);
  fs::remove_all(dir);

  const synthetic::SceneTruth& truth = scene.truth;
  EXPECT_EQ(stack.grid.width, truth.normal.width());
  EXPECT_EQ(stack.grid.height, truth.normal.height());
  const int w = std::min(stack.grid.width, truth.normal.width()), h = std::min(stack.grid.height, truth.normal.height());
  ChainErrors e;
  double height_mean = 0, truth_mean = 0, lo = 1e300, hi = -1e300;
  const double n = static_cast<double>(w) * h;
  for (int r = 0; r < h; ++r)
    for (int c = 0; c < w; ++c) {
      const Eigen::Vector3d t(truth.normal.at(0, r, c), truth.normal.at(1, r, c), truth.normal.at(2, r, c));
      const auto& ps = rec.photometric_stereo;
      const Eigen::Vector3d m(ps.normal.at(0, r, c), ps.normal.at(1, r, c), ps.normal.at(2, r, c));
      e.normal_deg += std::atan2(t.cross(m).norm(), t.dot(m)) * 180.0 / std::numbers::pi / n;
      const Rgb a{ps.albedo.at(0, r, c), ps.albedo.at(1, r, c), ps.albedo.at(2, r, c)};
      const Rgb b{truth.base_color.at(0, r, c), truth.base_color.at(1, r, c), truth.base_color.at(2, r, c)};
      e.albedo_de += Ciede2000(LinearSrgbToLab(a), LinearSrgbToLab(b)) / n;
      height_mean += rec.height_mm.at(0, r, c) / n;
      truth_mean += truth.height_mm.at(0, r, c) / n;
      lo = std::min(lo, static_cast<double>(truth.height_mm.at(0, r, c)));
      hi = std::max(hi, static_cast<double>(truth.height_mm.at(0, r, c)));
    }
  double s2 = 0;
  for (int r = 0; r < h; ++r)
    for (int c = 0; c < w; ++c) {
      const double d = (rec.height_mm.at(0, r, c) - height_mean) - (truth.height_mm.at(0, r, c) - truth_mean);
      s2 += d * d / n;
    }
  e.height_percent = 100.0 * std::sqrt(s2) / (hi - lo);
  std::printf("chain accuracy, bumps, %s rig, %dx%d px: normal %.3f deg, albedo CIEDE2000 %.3f, height %.2f %% of range\n",
              rig_name.c_str(), kCameraPixels, kCameraPixels, e.normal_deg, e.albedo_de, e.height_percent);
  return e;
}

class ChainAccuracy : public ::testing::TestWithParam<std::string> {
 protected:
  void SetUp() override { SetLogLevel(LogLevel::kError); }
};

TEST_P(ChainAccuracy, BumpsMeetTheIssueTargets) {
  const ChainErrors e = RunChain(GetParam());
  EXPECT_LT(e.normal_deg, kNormalTargetDeg);
  EXPECT_LT(e.albedo_de, kAlbedoTargetDe);
  EXPECT_LT(e.height_percent, kHeightTargetPercent);
}

INSTANTIATE_TEST_SUITE_P(Rigs, ChainAccuracy, ::testing::Values("distant", "near"),
                         [](const auto& info) { return info.param; });

}  // namespace
}  // namespace u3mscan
