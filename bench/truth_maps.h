#pragma once
// Ground-truth maps of a synthetic capture on disk: DIR/truth/*.exr + truth.json.
//
// WriteTruthMaps is a synthetic::TruthWriter (datasets_synthetic/capture_writer.h) that stores every
// map of a SceneTruth as float EXR and lists them in truth.json "maps"; ReadTruthMaps reads such a
// folder back (also one written by another truth writer, as long as truth.json lists its maps under
// "maps" or the files carry the default names below) together with the truth grid.
//
// Grid: truth pixel (col, row) centre lies at x = x0_mm + (col + 0.5) pitch_mm,
// y = y1_mm - (row + 0.5) pitch_mm in the world frame of the contract (mm, +x right, +y up), taken
// from truth.json "rig".sample_rect_mm [x0, y0, x1, y1] written by the capture writer; without it
// the grid is centred on the origin (docs/synthetic-scanner.md).

#include <filesystem>
#include <string>

#include "core/image.h"
#include "datasets_synthetic/scene.h"

namespace u3mscan::bench {

struct TruthMaps {
  std::string scene;
  double pitch_mm = 0.0;
  double x0_mm = 0.0;  // left edge of the truth grid
  double y1_mm = 0.0;  // top edge of the truth grid
  Image height_mm, normal, base_color, alpha;
  // index = fitting::FitParameter (roughness, specular, specular_tint, sheen, sheen_tint,
  // anisotropic, metallic); empty when the truth folder lacks that map.
  Image parameters[7];
};

// Default file names: <key>.exr with key height_mm, normal, base_color, alpha, roughness, specular,
// specular_tint, sheen, sheen_tint, anisotropic, metallic.
void WriteTruthMaps(const synthetic::SceneTruth& scene, const std::filesystem::path& truth_dir);

// Throws InputError naming truth.json or the map file when the folder cannot be read.
TruthMaps ReadTruthMaps(const std::filesystem::path& truth_dir);

}  // namespace u3mscan::bench
