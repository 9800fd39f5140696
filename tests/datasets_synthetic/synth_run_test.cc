#include "datasets_synthetic/synth_run.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <string>

#include "capture/manifest.h"
#include "core/error.h"

namespace u3mscan::synthetic {
namespace {

namespace fs = std::filesystem;

TEST(SynthRunTest, BadOptionsNameTheOption) {
  SynthOptions options;
  options.scene = "nonesuch";
  try {
    options.Check();
    FAIL() << "accepted an unknown scene";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), "--scene");
  }
  options.scene = "plain";
  options.rig = "far";
  EXPECT_THROW(options.Check(), InputError);
  options.rig = "near";
  options.width = 8;
  EXPECT_THROW(options.Check(), InputError);
  options.width = 64;
  options.dpi = -1;
  EXPECT_THROW(options.Check(), InputError);
  options.dpi = 300;
  EXPECT_NO_THROW(options.Check());
}

// A real scene preset end to end at the tiny size: the capture reads back and covers the scene.
TEST(SynthRunTest, PresetSceneWritesAReadableCapture) {
  const fs::path dir = fs::temp_directory_path() / ("u3mscan_synth_run_test_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  SynthOptions options;
  options.scene = "twill";
  options.rig = "distant";
  options.capture.calibration_frames = false;
  const CaptureStats stats = RunSynth(options, dir);
  const Manifest m = ReadManifest(dir / kCaptureSubdir);
  EXPECT_EQ(stats.frames, static_cast<int>(m.frames.size()));
  ASSERT_TRUE(m.output.region_mm.has_value());
  // The region is the scene grid: kSampleFillOfView of 64 pixels at 300 dpi.
  const double width_mm = (*m.output.region_mm)[2] - (*m.output.region_mm)[0];
  EXPECT_NEAR(width_mm, 48 * 25.4 / 300.0, 1e-9);
  EXPECT_TRUE(fs::exists(dir / kTruthSubdir / kTruthFileName));
  fs::remove_all(dir);
}

}  // namespace
}  // namespace u3mscan::synthetic
