#pragma once
// Ground-truth maps of a synthetic capture on disk: DIR/truth/*.exr + truth.json, as
// datasets_synthetic/truth_writer.h WriteTruth writes them (maps listed in truth.json "maps", or
// files with the default names below), read together with the grid the capture writer rendered
// the scene on.
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
  // The model the scene was rendered with (truth.json /reflectance_model; absent: principled, as
  // truth folders written before the field). The evaluation renders the truth with it.
  synthetic::ReflectanceModel model = synthetic::ReflectanceModel::kPrincipled;
  double pitch_mm = 0.0;
  double x0_mm = 0.0;  // left edge of the truth grid
  double y1_mm = 0.0;  // top edge of the truth grid
  Image height_mm, normal, base_color, alpha;
  Image tangent;  // 3 channels, fibre direction (the BRDF's local x); empty when absent
  // index = fitting::FitParameter (roughness, specular, specular_tint, sheen, sheen_tint,
  // anisotropic, metallic); empty when the truth folder lacks that map.
  Image parameters[7];
};

// Default file names: <key>.exr with key height_mm, normal, base_color, alpha, tangent, roughness,
// specular, specular_tint, sheen, sheen_tint, anisotropic, metallic.
// Throws InputError naming truth.json or the map file when the folder cannot be read, or naming
// /reflectance_model when it is not "principled" or "cloth_mismatch".
TruthMaps ReadTruthMaps(const std::filesystem::path& truth_dir);

}  // namespace u3mscan::bench
