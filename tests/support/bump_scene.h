#pragma once
// A small scene with known truth for end-to-end tests and probes of the pipeline: bumps
// z = a sin(kx) sin(ky), k = 2 pi / period, with uniform Principled parameters (base colour
// 0.6 0.4 0.3, roughness 0.6, specular 0.5, the rest 0, alpha 1), independent of the synthetic
// scanner's presets. Lengths in millimetres; x right, y up, rows growing with -y (scene frame of
// datasets_synthetic/scene.h).

#include <cmath>
#include <numbers>

#include "datasets_synthetic/scene.h"

namespace u3mscan::testing {

inline synthetic::SceneTruth BumpScene(int width, int height, double pitch_mm, double amplitude_mm,
                                        double period_mm) {
  synthetic::SceneTruth scene;
  scene.name = "bumps";
  scene.pitch_mm = pitch_mm;
  auto plane = [&](int channels, float value) { return Image(width, height, channels, value, pitch_mm); };
  scene.height_mm = plane(1, 0.0f);
  scene.normal = plane(3, 0.0f);
  const double k = 2.0 * std::numbers::pi / period_mm;
  for (int row = 0; row < height; ++row) {
    for (int col = 0; col < width; ++col) {
      const double x = (col + 0.5) * pitch_mm, y = -(row + 0.5) * pitch_mm;  // rows grow with -y
      scene.height_mm.at(0, row, col) = static_cast<float>(amplitude_mm * std::sin(k * x) * std::sin(k * y));
      const double dhdx = amplitude_mm * k * std::cos(k * x) * std::sin(k * y);
      const double dhdy = amplitude_mm * k * std::sin(k * x) * std::cos(k * y);
      const double norm = std::sqrt(dhdx * dhdx + dhdy * dhdy + 1.0);
      scene.normal.at(0, row, col) = static_cast<float>(-dhdx / norm);
      scene.normal.at(1, row, col) = static_cast<float>(-dhdy / norm);
      scene.normal.at(2, row, col) = static_cast<float>(1.0 / norm);
    }
  }
  scene.base_color = plane(3, 0.0f);
  const float base[3] = {0.6f, 0.4f, 0.3f};
  for (int c = 0; c < 3; ++c)
    for (float& v : scene.base_color.plane(c)) v = base[c];
  scene.roughness = plane(1, 0.6f);
  scene.specular = plane(1, 0.5f);
  scene.specular_tint = plane(1, 0.0f);
  scene.sheen = plane(1, 0.0f);
  scene.sheen_tint = plane(1, 0.0f);
  scene.metallic = plane(1, 0.0f);
  scene.anisotropic = plane(1, 0.0f);
  scene.alpha = plane(1, 1.0f);
  return scene;
}

}  // namespace u3mscan::testing
