#pragma once
// Tiny hand-made scenes for the scanner tests, independent of the scene presets (scene.h), so the
// renderer is checked against geometry the test fully controls.

#include "datasets_synthetic/scene.h"

namespace u3mscan::synthetic::testing {

// A flat sample of one diffuse colour: height 0, normal +z, no specular, no sheen.
inline SceneTruth FlatScene(int width, int height, double pitch_mm, float albedo) {
  SceneTruth s;
  s.name = "flat";
  s.pitch_mm = pitch_mm;
  s.height_mm = Image(width, height, 1, 0.0f, pitch_mm);
  s.normal = Image(width, height, 3, 0.0f, pitch_mm);
  for (float& z : s.normal.plane(2)) z = 1.0f;
  s.base_color = Image(width, height, 3, albedo, pitch_mm);
  s.roughness = Image(width, height, 1, 0.5f, pitch_mm);
  s.specular = Image(width, height, 1, 0.0f, pitch_mm);
  s.specular_tint = Image(width, height, 1, 0.0f, pitch_mm);
  s.sheen = Image(width, height, 1, 0.0f, pitch_mm);
  s.sheen_tint = Image(width, height, 1, 0.0f, pitch_mm);
  s.metallic = Image(width, height, 1, 0.0f, pitch_mm);
  s.anisotropic = Image(width, height, 1, 0.0f, pitch_mm);
  s.alpha = Image(width, height, 1, 1.0f, pitch_mm);
  s.tangent = Image(width, height, 3, 0.0f, pitch_mm);  // fibres along +x
  for (float& x : s.tangent.plane(0)) x = 1.0f;
  return s;
}

// FlatScene with a wall of `ridge_height_mm` on columns [col0, col1) (flat top, vertical sides).
inline SceneTruth RidgeScene(int width, int height, double pitch_mm, int col0, int col1, float ridge_height_mm) {
  SceneTruth s = FlatScene(width, height, pitch_mm, 0.5f);
  s.name = "ridge";
  for (int r = 0; r < height; ++r) {
    for (int c = col0; c < col1; ++c) s.height_mm.at(0, r, c) = ridge_height_mm;
  }
  s.height_max_mm = ridge_height_mm;
  return s;
}

}  // namespace u3mscan::synthetic::testing
