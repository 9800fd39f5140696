#pragma once
// RunSynth: what `u3mscan synth` does, by name: make the rig and the scene presets and write the
// capture folder with its truth (capture_writer.h). The CLI parses into SynthOptions and calls it.

#include <cstdint>
#include <filesystem>
#include <string>

#include "datasets_synthetic/capture_writer.h"

namespace u3mscan::synthetic {

// Largest --supersample: 64 rays per pixel.
inline constexpr int kMaxSupersample = 8;

// Everything `u3mscan synth` takes, by name: the CLI parses into this and calls RunSynth.
struct SynthOptions {
  std::string scene = "plain";  // SceneNames()
  std::string rig = "near";     // RigNames()
  int width = 64;               // camera pixels
  int height = 64;
  std::uint64_t seed = 1;
  double dpi = 300.0;           // the top camera's ground resolution and the scene's grid
  // Rays per camera pixel along each axis (a box filter over the pixel, RenderOptions); the scene
  // is sampled as many times finer than the output grid, memory permitting (SceneOversample).
  // 0 = AutoSupersample of the frame size. capture.supersample is overwritten with the choice.
  int supersample = 0;
  int lights = 0;               // light count, 0 = the rig preset's own (RigOptions::lights)
  bool sensor_noise = true;     // false: frames without sensor noise (SensorSpec::noise)
  CaptureOptions capture;
  // Throws InputError naming the option (e.g. "--scene") and what was expected.
  void Check() const;
};

// The sample covers this fraction of the top camera's view on each axis; the table shows around
// it (so the background and the sample's edge are in every frame, as on a real scanner).
inline constexpr double kSampleFillOfView = 0.75;

// The supersample RunSynth uses for `supersample` = 0 on a width x height camera: 3 (9 rays per
// pixel) up to 1.5 megapixels, 2 up to 12 megapixels, 1 above, so that the cached ray hits of one
// camera (12 bytes per ray) stay under ~600 MB and a 36-megapixel render stays affordable.
int AutoSupersample(int width, int height);

// Memory the fine scene may take (its 18 float maps): the oversampling factor is lowered until
// the scene fits. A 7360x4912 capture's scene (5520x3684 at the output grid) already needs 1.5 GB,
// so it is rendered from the output grid itself (factor 1).
inline constexpr double kMaxFineSceneBytes = 1.0 * (1 << 30);

// The factor the scene grid is made finer than the output grid: `supersample`, lowered while a
// scene_width x scene_height grid that many times finer would exceed kMaxFineSceneBytes; >= 1.
int SceneOversample(int supersample, int scene_width, int scene_height);

// A preset ready to render honestly: `fine` sampled `oversample` times finer than the output grid
// `grid` (SceneOversample of `supersample`), `truth` its area average on `grid`. Pass both to
// WriteSyntheticCapture(fine, truth, ...) with CaptureOptions::supersample = supersample.
struct OversampledScene {
  SceneTruth fine;
  SceneTruth truth;
  int oversample = 1;
};
OversampledScene MakeOversampledScene(const std::string& name, const SceneOptions& grid, int supersample);

// Makes the rig and the scene (output grid = the rig's ground pitch, kSampleFillOfView of the
// view), renders a SceneOversample-times finer sampling of the fabric with `supersample` rays per
// pixel, and writes DIR with WriteSyntheticCapture; the truth is the fine scene's area average on
// the output grid (AreaAverageScene).
CaptureStats RunSynth(const SynthOptions& options, const std::filesystem::path& out_dir,
                      const TruthWriter& truth_writer = {});

}  // namespace u3mscan::synthetic
