#pragma once
// Scene presets of the synthetic scanner: procedural fabric samples with their ground truth.
// A scene is a height field with per-pixel Principled parameters on a metric grid; the renderer
// (renderer.h) lights and photographs it, the truth writer stores it as float EXR maps.
//
// Units: heights in mm (+z toward the camera), grid pitch in mm; colours linear RGB.

#include <cstdint>
#include <string>
#include <vector>

#include "core/image.h"

namespace u3mscan::synthetic {

// Which reflectance model the renderer uses for this scene. kPrincipled is the model the fitter
// fits; kClothMismatch adds a lobe of another family (see renderer.h) so tests can measure model
// mismatch.
enum class ReflectanceModel { kPrincipled, kClothMismatch };

// Ground truth of one sample, every map on the same grid (width x height, pitch_mm).
struct SceneTruth {
  std::string name;
  double pitch_mm = 0.0;
  Image height_mm;       // 1 channel, mm
  Image normal;          // 3 channels, unit, world frame (x right, y up, z out of the fabric)
  Image base_color;      // 3 channels, linear RGB
  Image roughness;       // 1 channel
  Image specular;        // 1 channel
  Image specular_tint;   // 1 channel
  Image sheen;           // 1 channel
  Image sheen_tint;      // 1 channel
  Image metallic;        // 1 channel, 0 for fabric
  Image anisotropic;     // 1 channel
  Image alpha;           // 1 channel, 0 in holes, 1 on fabric
  ReflectanceModel model = ReflectanceModel::kPrincipled;
};

struct SceneOptions {
  int width = 64;
  int height = 64;
  double pitch_mm = 25.4 / 300.0;  // 300 dpi
  std::uint64_t seed = 1;
};

// Names accepted by MakeScene: plain, twill, satin, knit, denim, velvet, lace, and the extreme
// presets (dark, bright, mirror, pure_velvet, holes, ...; see SceneNames()).
std::vector<std::string> SceneNames();
// Deterministic from options.seed. Throws std::invalid_argument for an unknown name.
SceneTruth MakeScene(const std::string& name, const SceneOptions& options);

}  // namespace u3mscan::synthetic
