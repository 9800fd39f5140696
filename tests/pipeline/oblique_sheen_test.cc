// Issue 6, "Multi-view: use the oblique camera when the capture has one; sheen must be recovered
// then", through the whole chain: the synthetic scanner's `velvet_bumps` (the velvet preset's
// material, uniform, on the smooth egg-crate bumps, so that one normal per map pixel describes the
// surface) rendered on the `oblique` rig (16 near lights, the top camera and a 60 deg oblique one)
// and on the `near` rig (the same lights, the top camera only), processed by ProcessCapture and
// compared with the truth by bench::Evaluate (`u3mscan evaluate`).
//
// The velvet preset itself (a cut pile whose fibre tips are finer than a map pixel) gives sheen
// 0.2-0.3 low on the same rig: that is the one-normal-per-pixel model against a pile, measured
// in docs/fitting.md ("Sheen with the oblique camera"); this test holds the chain to the issue's
// targets where the model describes the surface.
#include <gtest/gtest.h>

#include <iostream>
#include <string>

#include "bench/evaluate.h"
#include "datasets_synthetic/synth_run.h"
#include "pipeline/process.h"
#include "tests/support/temp_dir.h"

namespace u3mscan {
namespace {

// Issue 6 targets (absolute errors of the fitted maps against the truth).
constexpr double kRoughnessTolerance = 0.05;
constexpr double kSpecularTolerance = 0.1;
constexpr double kSheenTolerance = 0.1;
// Not an issue target: sheen tint and anisotropy have none; the bound says they are measured, not
// guessed (measured at 64 px, fast: sheen tint 0.001, anisotropic 0.032).
constexpr double kSheenTintTolerance = 0.1;
constexpr double kAnisotropicTolerance = 0.1;
constexpr int kCameraPixels = 64;

bench::Evaluation ProcessVelvetBumps(const test::TempDir& dir, const std::string& rig) {
  synthetic::SynthOptions synth;
  synth.scene = "velvet_bumps";
  synth.rig = rig;
  synth.width = synth.height = kCameraPixels;
  synth.capture.format = synthetic::FrameFormat::kTiff;
  synth.capture.calibration_frames = false;  // geometry and colour from the manifest
  synthetic::RunSynth(synth, dir / rig);
  ProcessOptions options;
  options.preset = Preset::kFast;
  options.debug_maps = true;  // maps/*.exr for the evaluation
  const CaptureJob job{dir / rig / synthetic::kCaptureSubdir, dir / (rig + "_out"), "velvet_bumps"};
  ProcessCapture(job, options);
  const bench::Evaluation e = bench::Evaluate(job.out_dir, dir / rig / synthetic::kTruthSubdir);
  std::cout << "[ MEASURED ] velvet_bumps / " << rig << "\n" << bench::EvaluationToText(e);
  return e;
}

TEST(ObliqueSheen, TheObliqueCameraMeasuresEveryLobeOfTheVelvetWithinTheIssueTargets) {
  test::TempDir dir;
  const bench::Evaluation e = ProcessVelvetBumps(dir, "oblique");
  ASSERT_GT(e.pixels_compared, 0);
  struct Target {
    const char* name;
    double tolerance;
  };
  for (const Target& t : {Target{"roughness", kRoughnessTolerance}, Target{"specular", kSpecularTolerance},
                          Target{"sheen", kSheenTolerance}, Target{"sheen_tint", kSheenTintTolerance},
                          Target{"anisotropic", kAnisotropicTolerance}}) {
    const bench::ParameterError& p = bench::FindParameter(e, t.name);
    ASSERT_TRUE(p.measured) << t.name << " was left out";
    EXPECT_TRUE(p.reliable) << t.name << " was flagged";
    EXPECT_LT(p.mean_abs_error, t.tolerance)
        << t.name << ": material mean " << p.estimate_mean << ", truth " << p.truth_mean;
  }
}

// The same lights and sample without the oblique camera: sheen cannot be told from the diffuse
// lobe by a camera straight above, so it is left out (the U3M default, "not measured"), whereas
// the lobes the overhead view does measure stay within the targets.
TEST(ObliqueSheen, WithoutTheObliqueCameraSheenIsLeftOut) {
  test::TempDir dir;
  const bench::Evaluation e = ProcessVelvetBumps(dir, "near");
  ASSERT_GT(e.pixels_compared, 0);
  EXPECT_FALSE(bench::FindParameter(e, "sheen").measured);
  EXPECT_FALSE(bench::FindParameter(e, "sheen_tint").measured);
  const bench::ParameterError& roughness = bench::FindParameter(e, "roughness");
  ASSERT_TRUE(roughness.measured);
  EXPECT_LT(roughness.mean_abs_error, kRoughnessTolerance);
}

}  // namespace
}  // namespace u3mscan
