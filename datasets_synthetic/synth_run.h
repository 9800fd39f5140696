#pragma once
// RunSynth: what `u3mscan synth` does, by name: make the rig and the scene presets and write the
// capture folder with its truth (capture_writer.h). The CLI parses into SynthOptions and calls it.

#include <cstdint>
#include <filesystem>
#include <string>

#include "datasets_synthetic/capture_writer.h"

namespace u3mscan::synthetic {

// Everything `u3mscan synth` takes, by name: the CLI parses into this and calls RunSynth.
struct SynthOptions {
  std::string scene = "plain";  // SceneNames()
  std::string rig = "near";     // RigNames()
  int width = 64;               // camera pixels
  int height = 64;
  std::uint64_t seed = 1;
  double dpi = 300.0;           // the top camera's ground resolution and the scene's grid
  int lights = 0;               // light count, 0 = the rig preset's own (RigOptions::lights)
  CaptureOptions capture;
  // Throws InputError naming the option (e.g. "--scene") and what was expected.
  void Check() const;
};

// The sample covers this fraction of the top camera's view on each axis; the table shows around
// it (so the background and the sample's edge are in every frame, as on a real scanner).
inline constexpr double kSampleFillOfView = 0.75;

// Makes the rig and the scene (scene grid = the rig's ground pitch, kSampleFillOfView of the
// view) and writes DIR with WriteSyntheticCapture.
CaptureStats RunSynth(const SynthOptions& options, const std::filesystem::path& out_dir,
                      const TruthWriter& truth_writer = {});

}  // namespace u3mscan::synthetic
