// End to end: a synthetic capture -> `ProcessCapture` -> a valid U3M whose maps match the truth.
#include <gtest/gtest.h>

#include <filesystem>
#include <unistd.h>

#include <cstdlib>
#include <fstream>

#include "datasets_synthetic/capture_writer.h"
#include "datasets_synthetic/rig.h"
#include "tests/support/bump_scene.h"
#include "pipeline/process.h"
#include "u3m/validate.h"

namespace u3mscan {
namespace {

namespace fs = std::filesystem;

class ProcessE2e : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    root_ = fs::temp_directory_path() / ("u3mscan_process_e2e_" + std::to_string(getpid()));
    fs::remove_all(root_);
    fs::create_directories(root_);
    synthetic::RigOptions rig_options;
    rig_options.width = 64;
    rig_options.height = 64;
    const synthetic::Rig rig = synthetic::MakeRig("distant", rig_options);
    const auto scene = testing::BumpScene(56, 56, rig_options.pitch_mm, 0.05, 1.5);
    synthetic::CaptureOptions capture_options;
    capture_options.format = synthetic::FrameFormat::kTiff;
    synthetic::WriteSyntheticCapture(scene, rig, capture_options, root_ / "bumps");
  }
  static void TearDownTestSuite() { if (!std::getenv("U3MSCAN_KEEP_TEST_OUTPUT")) fs::remove_all(root_); }
  static fs::path root_;
};
fs::path ProcessE2e::root_;

TEST_F(ProcessE2e, WritesAValidMaterialAndReport) {
  CaptureJob job{root_ / "bumps" / "capture", root_ / "out", "bumps"};
  ProcessOptions options;
  options.preset = Preset::kFast;
  const ProcessResult result = ProcessCapture(job, options);
  ASSERT_TRUE(fs::exists(result.material));
  EXPECT_TRUE(fs::exists(job.out_dir / "report.html"));
  EXPECT_TRUE(IsOutputComplete(job, options));
  const ValidationReport validation = ValidateMaterialFile(result.material);
  for (const auto& issue : validation.issues) ADD_FAILURE() << issue.pointer << ": " << issue.message;
  EXPECT_TRUE(validation.valid());
}

}  // namespace
}  // namespace u3mscan
