#include "datasets_synthetic/synth_run.h"

#include <algorithm>
#include <cmath>

#include "core/elapsed.h"
#include "core/error.h"
#include "core/logging.h"
#include "core/units.h"
#include "datasets_synthetic/rig.h"
#include "datasets_synthetic/scene.h"

namespace u3mscan::synthetic {

namespace fs = std::filesystem;

void SynthOptions::Check() const {
  auto one_of = [](const std::vector<std::string>& names) {
    std::string list;
    for (const auto& n : names) list += (list.empty() ? "" : ", ") + n;
    return "one of " + list;
  };
  const auto scenes = SceneNames(), rigs = RigNames();
  if (std::find(scenes.begin(), scenes.end(), scene) == scenes.end()) throw InputError("--scene", "", one_of(scenes) + ", got '" + scene + "'");
  if (std::find(rigs.begin(), rigs.end(), rig) == rigs.end()) throw InputError("--rig", "", one_of(rigs) + ", got '" + rig + "'");
  // The DNG writer needs 22 pixels a side (libraw's thumbnail limit); 65536 is the frame limit.
  constexpr int kMinSide = 32, kMaxSide = 1 << 16;
  if (width < kMinSide || height < kMinSide || width > kMaxSide || height > kMaxSide) {
    throw InputError("--size", "", "WxH with each side in [" + std::to_string(kMinSide) + ", " + std::to_string(kMaxSide) + "]");
  }
  // Photometric stereo needs 3 lights; 256 keeps the ids L00..L255 and the stack size sane.
  constexpr int kMinLights = 3, kMaxLights = 256;
  if (lights != 0 && (lights < kMinLights || lights > kMaxLights)) {
    throw InputError("--lights", "", "0 (the rig's own count) or a count in [" + std::to_string(kMinLights) + ", " +
                                         std::to_string(kMaxLights) + "], got " + std::to_string(lights));
  }
  if (rig == "single_light" && lights != 0 && lights != 8) {
    throw InputError("--lights", "", "8 (or 0) for rig single_light, which has one light per aim point");
  }
  if (!(dpi >= 10.0 && dpi <= 20000.0)) throw InputError("--dpi", "", "a resolution in [10, 20000] dots per inch");
  if (supersample < 0 || supersample > kMaxSupersample) {
    throw InputError("--supersample", "", "0 (auto) or rays per pixel axis in [1, " + std::to_string(kMaxSupersample) + "]");
  }
}

int AutoSupersample(int width, int height) {
  const double megapixels = 1e-6 * width * height;
  if (megapixels <= 1.5) return 3;
  if (megapixels <= 12.0) return 2;
  return 1;
}

int SceneOversample(int supersample, int scene_width, int scene_height) {
  constexpr double kSceneBytesPerPixel = 18 * sizeof(float);  // SceneTruth: 18 float channels
  int factor = std::max(1, supersample);
  while (factor > 1 && kSceneBytesPerPixel * scene_width * scene_height * factor * factor > kMaxFineSceneBytes) --factor;
  return factor;
}

OversampledScene MakeOversampledScene(const std::string& name, const SceneOptions& grid, int supersample) {
  OversampledScene s;
  s.oversample = SceneOversample(supersample, grid.width, grid.height);
  s.fine = MakeScene(name, OversampledSceneOptions(grid, s.oversample));
  s.truth = AreaAverageScene(s.fine, s.oversample);
  return s;
}

CaptureStats RunSynth(const SynthOptions& options, const fs::path& out_dir, const TruthWriter& truth_writer) {
  options.Check();
  RigOptions rig_options;
  rig_options.width = options.width;
  rig_options.height = options.height;
  rig_options.pitch_mm = DpiToPitchMm(options.dpi);
  rig_options.seed = options.seed;
  rig_options.lights = options.lights;
  Rig rig = MakeRig(options.rig, rig_options);
  rig.sensor.noise = options.sensor_noise;
  SceneOptions scene_options;
  scene_options.width = std::max(1, static_cast<int>(std::lround(kSampleFillOfView * options.width)));
  scene_options.height = std::max(1, static_cast<int>(std::lround(kSampleFillOfView * options.height)));
  scene_options.pitch_mm = rig_options.pitch_mm;
  scene_options.seed = options.seed;
  const int supersample = options.supersample > 0 ? options.supersample : AutoSupersample(options.width, options.height);
  const double start = SteadySeconds();
  const OversampledScene scene = MakeOversampledScene(options.scene, scene_options, supersample);
  LogInfo() << "synth: scene '" << options.scene << "' " << scene_options.width << "x" << scene_options.height << " at "
            << options.dpi << " dpi, sampled " << scene.oversample << "x finer, " << supersample << "x" << supersample
            << " rays per pixel; made in " << SteadySeconds() - start << " s";
  CaptureOptions capture = options.capture;
  capture.supersample = supersample;
  return WriteSyntheticCapture(scene.fine, scene.truth, rig, capture, out_dir, truth_writer);
}

}  // namespace u3mscan::synthetic
