#pragma once
// Scene presets of the synthetic scanner: procedural fabric samples with their ground truth.
// A scene is a height field with per-pixel Principled parameters on a metric grid; the renderer
// (renderer.h) lights and photographs it, the truth writer stores it as float EXR maps.
//
// Units: heights in mm (+z toward the camera), grid pitch in mm; colours linear RGB.
// Grid: pixel (row, col) is the point sample of the fabric at x_mm = origin_x_mm + col * pitch_mm,
// y_mm = origin_y_mm - row * pitch_mm (world frame: x right, y up, z out of the fabric; rows grow
// with -y; the origin is 0 unless SceneOptions says otherwise).
// The pattern is a function of (x_mm, y_mm) and the seed only, so a grid at twice the dpi samples
// the same physical fabric: pixel (2r, 2c) at pitch p/2 equals pixel (r, c) at pitch p.
//
// A camera pixel integrates light over its area, so the synthetic scanner renders a scene sampled
// `factor` times finer than the output grid (OversampledSceneOptions) and writes as truth the area
// average of that fine scene over each output pixel (AreaAverageScene).
// The presets are described in docs/synthetic-scenes.md.

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "core/image.h"

namespace u3mscan::synthetic {

// Which reflectance model the renderer uses for this scene. kPrincipled is the model the fitter
// fits; kClothMismatch adds a lobe of another family (see renderer.h) so tests can measure model
// mismatch.
enum class ReflectanceModel { kPrincipled, kClothMismatch };

// The model's name in truth.json /reflectance_model: "principled" or "cloth_mismatch".
const char* ReflectanceModelName(ReflectanceModel model);
// The model a truth.json name stands for; false (and *model untouched) for any other name.
bool ParseReflectanceModel(const std::string& name, ReflectanceModel* model);
// What ParseReflectanceModel accepts, for error messages: "\"principled\" or \"cloth_mismatch\"".
std::string ReflectanceModelChoices();

// Nominal Principled parameters of one yarn (or surface) of a scene, before the per-thread and
// per-fibre variation that the maps carry. Geometry in mm (0 where it does not apply).
struct YarnTruth {
  std::string name;                     // "warp", "weft", "pile", "net", ...
  std::array<float, 3> base_color{};    // linear RGB
  float roughness = 0.5f;
  float specular = 0.5f;
  float specular_tint = 0.0f;
  float sheen = 0.0f;
  float sheen_tint = 0.0f;
  float metallic = 0.0f;
  float anisotropic = 0.0f;
  double width_mm = 0.0;      // yarn width across its axis
  double thickness_mm = 0.0;  // crown height of the yarn cross-section
  double spacing_mm = 0.0;    // centre-to-centre distance of neighbouring threads
};

// Ground truth of one sample, every map on the same grid (width x height, pitch_mm).
struct SceneTruth {
  std::string name;
  double pitch_mm = 0.0;
  std::uint64_t seed = 0;
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
  // 3 channels, unit, world frame: the fibre direction of the visible yarn (the BRDF's local x,
  // the axis of anisotropy), already orthogonal to `normal`. Bitangent = normal x tangent.
  Image tangent;
  ReflectanceModel model = ReflectanceModel::kPrincipled;

  // Bounds that every height of this preset lies in, for every seed and grid (mm).
  double height_min_mm = 0.0;
  double height_max_mm = 0.0;
  // Physical repeat of the weave/knit/lace pattern along x and y (mm); 0 = not periodic.
  double repeat_x_mm = 0.0;
  double repeat_y_mm = 0.0;
  std::string description;       // one line: structure and what the preset tests
  std::vector<YarnTruth> yarns;  // nominal values per yarn, for truth.json and the fit report
};

struct SceneOptions {
  int width = 64;
  int height = 64;
  double pitch_mm = 25.4 / 300.0;  // 300 dpi
  std::uint64_t seed = 1;
  // Pattern position (mm) of pixel (0, 0); see the grid note above. 0 for a preset's own grid.
  double origin_x_mm = 0.0;
  double origin_y_mm = 0.0;
  // True when width, height >= 1, 0 < pitch_mm and the origin are finite.
  bool Check() const;
};

// Names accepted by MakeScene: plain, twill, satin, knit, denim, velvet, lace, and the extreme and
// analytic presets (dark, bright, mirror, pure_velvet, holes, flat_lambertian, sphere_cap, bumps,
// velvet_bumps, velvet_mismatch; see SceneNames()).
std::vector<std::string> SceneNames();
// Deterministic from options.seed, independent of the thread count. Throws std::invalid_argument
// for an unknown name or options that fail Check().
SceneTruth MakeScene(const std::string& name, const SceneOptions& options);

// Pattern position (mm) of a pixel centre on a scene grid with origin 0 (see the grid note above).
inline double PixelXMm(int col, double pitch_mm) { return col * pitch_mm; }
inline double PixelYMm(int row, double pitch_mm) { return -row * pitch_mm; }

// The grid `factor` (>= 1) times finer on each axis that tiles exactly the footprints of the
// pixels of `coarse`: coarse pixel (c, r), centred on the pattern point (x, y) and one pitch p
// wide, holds fine pixels (f c + i, f r + j), i, j < f, centred at x + ((i + 0.5) / f - 0.5) p,
// y - ((j + 0.5) / f - 0.5) p. factor 1 returns `coarse`.
SceneOptions OversampledSceneOptions(const SceneOptions& coarse, int factor);

// The truth of a scene on the grid `factor` times coarser than `fine` (made with
// OversampledSceneOptions): each coarse pixel is the area average (midpoint rule over its
// factor^2 fine pixels) of what the fine scene holds over its footprint. Heights, colours and the
// Principled parameters are averaged, alpha is the covered fraction, normals are averaged then made
// unit, tangents averaged, made orthogonal to that normal and unit. Scene-level fields (name,
// seed, model, bounds, repeat, yarns) are copied; pitch_mm = factor * fine.pitch_mm. fine's size
// must be a multiple of factor (std::invalid_argument otherwise).
SceneTruth AreaAverageScene(const SceneTruth& fine, int factor);

}  // namespace u3mscan::synthetic
