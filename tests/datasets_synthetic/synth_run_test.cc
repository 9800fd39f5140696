#include "datasets_synthetic/synth_run.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <set>
#include <string>

#include "capture/manifest.h"
#include "core/error.h"
#include "datasets_synthetic/rig.h"
#include "datasets_synthetic/sensor.h"
#include "datasets_synthetic/truth_writer.h"
#include "tests/support/temp_dir.h"
#include "u3m/image_io.h"

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
  for (int bad : {-1, kMaxSupersample + 1}) {
    options.supersample = bad;
    try {
      options.Check();
      FAIL() << "accepted supersample " << bad;
    } catch (const InputError& e) {
      EXPECT_EQ(e.file(), "--supersample");
    }
  }
  options.supersample = 0;
  options.lights = 2;  // photometric stereo needs three
  try {
    options.Check();
    FAIL() << "accepted 2 lights";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), "--lights");
  }
  options.lights = 32;
  EXPECT_NO_THROW(options.Check());
  options.rig = "single_light";  // one light per aim point: only its own 8
  EXPECT_THROW(options.Check(), InputError);
}

TEST(SynthRunTest, AutoSupersampleAndSceneOversampleKeepMemoryBounded) {
  EXPECT_EQ(AutoSupersample(256, 256), 3);
  EXPECT_EQ(AutoSupersample(1000, 1000), 3);
  EXPECT_EQ(AutoSupersample(4000, 3000), 2);
  EXPECT_EQ(AutoSupersample(7360, 4912), 1);
  EXPECT_EQ(SceneOversample(3, 192, 192), 3);
  // A 7360x4912 camera's scene grid (kSampleFillOfView): over the budget even 2x finer.
  EXPECT_EQ(SceneOversample(3, 5520, 3684), 1);
  EXPECT_EQ(SceneOversample(0, 10, 10), 1);
  for (int side : {1000, 2000, 3000}) {
    const int f = SceneOversample(3, side, side);
    EXPECT_LE(18.0 * sizeof(float) * side * side * f * f, kMaxFineSceneBytes + (f == 1 ? 1e12 : 0.0)) << side;
  }
}

// --lights N: N lights on the rig's rings, unique ids, the default count unchanged, and the ring
// elevations kept (each light within the preset's +-2 deg elevation jitter of one of its rings).
TEST(SynthRunTest, LightCountSpreadsOverTheRings) {
  RigOptions options;
  const Rig preset = MakeRig("near", options);
  EXPECT_EQ(preset.lights.size(), 16u);
  options.lights = 16;
  const Rig sixteen = MakeRig("near", options);
  ASSERT_EQ(sixteen.lights.size(), 16u);
  for (std::size_t i = 0; i < 16; ++i) EXPECT_EQ(sixteen.lights[i].position_mm, preset.lights[i].position_mm) << i;

  constexpr double kRingJitterDeg = 2.0 + 1e-9;  // AddRings' elevation jitter, plus rounding
  for (const char* name : {"near", "distant"}) {
    options.lights = 33;  // odd: the first ring takes 17
    const Rig rig = MakeRig(name, options);
    ASSERT_EQ(rig.lights.size(), 33u) << name;
    std::set<std::string> ids;
    int low_ring = 0;
    for (const RigLight& light : rig.lights) {
      ids.insert(light.id);
      const Eigen::Vector3d dir = light.type == RigLightType::kPoint ? light.position_mm.normalized() : light.direction;
      const double elevation = std::asin(dir.z()) * 180.0 / M_PI;
      const bool on_low = std::abs(elevation - 30.0) <= kRingJitterDeg;
      const double high = std::string(name) == "near" ? 55.0 : 60.0;
      EXPECT_TRUE(on_low || std::abs(elevation - high) <= kRingJitterDeg) << name << " " << light.id << " " << elevation;
      low_ring += on_low;
    }
    EXPECT_EQ(ids.size(), 33u) << name;
    EXPECT_EQ(low_ring, 17) << name;
  }
  options.lights = 20;
  EXPECT_EQ(MakeRig("grazing", options).lights.size(), 20u);
  EXPECT_EQ(MakeRig("coplanar", options).lights.size(), 20u);
  EXPECT_THROW(MakeRig("single_light", options), std::invalid_argument);
}

// A real scene preset end to end at the tiny size: the capture reads back and covers the scene.
TEST(SynthRunTest, PresetSceneWritesAReadableCapture) {
  const test::TempDir temp;  // removed however the test ends
  const fs::path& dir = temp.path();
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
  // The output grid is the truth's 300 dpi, not the 3x finer grid the frames were rendered from.
  ASSERT_TRUE(m.output.dpi.has_value());
  EXPECT_NEAR(*m.output.dpi, 300.0, 1e-9);
  // The truth is the area average of the 3x finer scene (auto supersample at 64x64 is 3).
  const SceneTruth truth = ReadTruth(dir / kTruthSubdir);
  SceneOptions grid;
  grid.width = grid.height = 48;
  grid.pitch_mm = 25.4 / 300.0;
  grid.seed = options.seed;
  const SceneTruth expected = AreaAverageScene(MakeScene("twill", OversampledSceneOptions(grid, 3)), 3);
  EXPECT_NEAR(truth.pitch_mm, grid.pitch_mm, 1e-12);
  EXPECT_EQ(truth.height_mm.data(), expected.height_mm.data());
  EXPECT_EQ(truth.normal.data(), expected.normal.data());
}

// --no-noise: the same capture without the sensor's noise. A sample frame then differs from the
// noisy one by the noise alone (no more than kNoiseOnlyBound of the sensor's sigma at full scale,
// RMS over the frame, and not 0), and truth.json says which it is.
constexpr double kNoiseOnlyBound = 1.0;

TEST(SynthRunTest, WithoutNoiseTheSameCaptureIsWrittenWithoutItsSensorNoise) {
  const test::TempDir temp;
  const fs::path& dir = temp.path();
  SynthOptions options;
  options.scene = "plain";
  options.rig = "distant";
  options.capture.calibration_frames = false;
  options.capture.format = FrameFormat::kTiff;
  RunSynth(options, dir / "noisy");
  options.sensor_noise = false;
  RunSynth(options, dir / "clean");
  const Manifest m = ReadManifest(dir / "clean" / kCaptureSubdir);
  const FrameSpec& sample = *std::find_if(m.frames.begin(), m.frames.end(),
                                          [](const FrameSpec& f) { return f.role == FrameRole::kSample; });
  const Image clean = ReadImageFile(dir / "clean" / kCaptureSubdir / sample.file, PixelEncoding::kLinear);
  const Image noisy = ReadImageFile(dir / "noisy" / kCaptureSubdir / sample.file, PixelEncoding::kLinear);
  ASSERT_EQ(clean.data().size(), noisy.data().size());
  double diff2 = 0.0;
  for (std::size_t i = 0; i < clean.data().size(); ++i) diff2 += std::pow(clean.data()[i] - noisy.data()[i], 2);
  const double rms = std::sqrt(diff2 / static_cast<double>(clean.data().size()));
  const SensorSpec sensor;
  EXPECT_GT(rms, 0.0) << "the noise was not taken out";
  EXPECT_LT(rms, kNoiseOnlyBound * NoiseSigma(sensor, 1.0)) << "more than the noise differs";
  nlohmann::json clean_truth, noisy_truth;
  ReadTruth(dir / "clean" / kTruthSubdir, &clean_truth);
  ReadTruth(dir / "noisy" / kTruthSubdir, &noisy_truth);
  EXPECT_EQ(clean_truth["rig"]["sensor"]["noise"], false);
  EXPECT_EQ(noisy_truth["rig"]["sensor"]["noise"], true);
}

}  // namespace
}  // namespace u3mscan::synthetic
