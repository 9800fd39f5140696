// Footprint-roughness probe (not a test, not run by ctest, not in the default build): the
// roughness a pixel's highlight shows when the facets under the pixel slope different ways.
//
// A pixel that averages facets of several slopes reflects the sum of their lobes, each centred on
// its own facet's mirror direction: a lobe wider than any facet's. With a Beckmann-like slope
// distribution (slope variance alpha^2 / 2 per axis of the fibre frame) the footprint's lobe is
// matched by alpha_eff^2 = mean(alpha^2) + 2 var(slope) per axis, the filtering rule of LEAN and
// Toksvig maps. The probe samples the scene SAMPLES times finer than a CAMERA_DPI camera pixel
// (OversampledSceneOptions), takes each footprint's slope covariance in its mean fibre frame, and
// gives the matched Principled roughness and anisotropic (core/principled_brdf.h:
// alpha_t = r^2 / aspect, alpha_b = r^2 aspect, aspect = sqrt(1 - 0.9 anisotropic)) for three
// footprints: one sample (the scene's own values), a camera pixel, a map pixel at MAPS_DPI.
// SAMPLES = 3 is what the synthetic scanner renders (3x3 rays on a 3x finer scene); more samples
// add the slopes finer than that, which a real fabric has too. GGX's slope variance is not finite,
// so the 2 var rule is an approximation: read the figures as how far the lobe widens, not as a
// truth to 0.01.
//
// Build and run:
//   cmake --build build --target fitting_footprint_roughness_probe
//   build/tests/fitting/fitting_footprint_roughness_probe SCENE [CAMERA_DPI=1200] [MAPS_DPI=300] [SAMPLES=3] [SIZE_MM=4]
// Figures in docs/fitting.md ("What widens the satin's lobe").
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

#include "core/principled_brdf.h"
#include "datasets_synthetic/scene.h"

using namespace u3mscan;

namespace {

// What one footprint size gives, summed over its footprints.
struct FootprintTally {
  int footprints = 0;
  double roughness = 0.0;      // matched Principled roughness
  double anisotropic = 0.0;    // matched anisotropic, 0..1
  int stretched_across = 0;    // footprints whose lobe is longer across the fibres than along them
  double slope_var_along = 0.0;   // slope variance along the mean fibre direction
  double slope_var_across = 0.0;  // and across it
  double scene_roughness = 0.0;   // the scene's own roughness, averaged
};

// Tallies every b x b footprint of `scene` that lies on fabric (alpha >= 0.5 throughout).
FootprintTally TallyFootprints(const synthetic::SceneTruth& scene, int b) {
  FootprintTally tally;
  const int rows = scene.normal.height() / b, cols = scene.normal.width() / b;
  for (int br = 0; br < rows; ++br) {
    for (int bc = 0; bc < cols; ++bc) {
      double sx = 0, sy = 0, sxx = 0, syy = 0, sxy = 0, tx = 0, ty = 0, at2 = 0, ab2 = 0, r = 0;
      bool fabric = true;
      for (int row = br * b; row < (br + 1) * b && fabric; ++row) {
        for (int col = bc * b; col < (bc + 1) * b; ++col) {
          if (scene.alpha.at(0, row, col) < 0.5f) {
            fabric = false;
            break;
          }
          // Surface slopes dz/dx, dz/dy of the facet (world frame, x right, y up).
          const double nz = std::max(0.05, static_cast<double>(scene.normal.at(2, row, col)));
          const double gx = -scene.normal.at(0, row, col) / nz, gy = -scene.normal.at(1, row, col) / nz;
          sx += gx, sy += gy, sxx += gx * gx, syy += gy * gy, sxy += gx * gy;
          tx += scene.tangent.at(0, row, col), ty += scene.tangent.at(1, row, col);
          float alpha_t = 0.0f, alpha_b = 0.0f;
          brdf::AnisotropicAlphas(scene.roughness.at(0, row, col), scene.anisotropic.at(0, row, col), &alpha_t, &alpha_b);
          at2 += double(alpha_t) * alpha_t, ab2 += double(alpha_b) * alpha_b;
          r += scene.roughness.at(0, row, col);
        }
      }
      if (!fabric) continue;
      const double n = double(b) * b;
      const double mx = sx / n, my = sy / n;
      const double vxx = sxx / n - mx * mx, vyy = syy / n - my * my, vxy = sxy / n - mx * my;
      // The footprint's fibre direction in plan (its facets' tangents averaged); x when they cancel.
      double len = std::hypot(tx, ty);
      if (len < 1e-9) tx = 1.0, ty = 0.0, len = 1.0;
      const double ux = tx / len, uy = ty / len;
      const double var_along = ux * ux * vxx + 2 * ux * uy * vxy + uy * uy * vyy;
      const double var_across = uy * uy * vxx - 2 * ux * uy * vxy + ux * ux * vyy;
      const double alpha_along = std::sqrt(at2 / n + 2.0 * var_along);
      const double alpha_across = std::sqrt(ab2 / n + 2.0 * var_across);
      const double ratio = std::min(alpha_along, alpha_across) / std::max(alpha_along, alpha_across);
      ++tally.footprints;
      tally.roughness += std::pow(alpha_along * alpha_across, 0.25);
      tally.anisotropic += std::clamp((1.0 - ratio) / 0.9, 0.0, 1.0);  // ratio = aspect^2
      tally.stretched_across += alpha_across > alpha_along ? 1 : 0;
      tally.slope_var_along += var_along;
      tally.slope_var_across += var_across;
      tally.scene_roughness += r / n;
    }
  }
  return tally;
}

void Print(const char* what, int b, double dpi, const FootprintTally& t) {
  if (t.footprints == 0) {
    std::printf("%-12s no footprint on fabric\n", what);
    return;
  }
  const double k = 1.0 / t.footprints;
  std::printf("%-12s %3d samples a side (%6.0f dpi): roughness %.3f anisotropic %.3f (lobe longer across the fibres in %4.1f %%)"
              " slope var along %.4f across %.4f | scene roughness %.3f\n",
              what, b, dpi, t.roughness * k, t.anisotropic * k, 100.0 * t.stretched_across * k, t.slope_var_along * k,
              t.slope_var_across * k, t.scene_roughness * k);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s SCENE [CAMERA_DPI=1200] [MAPS_DPI=300] [SAMPLES=3] [SIZE_MM=4]\n", argv[0]);
    return 2;
  }
  const std::string scene_name = argv[1];
  const double camera_dpi = argc > 2 ? std::stod(argv[2]) : 1200.0;
  const double maps_dpi = argc > 3 ? std::stod(argv[3]) : 300.0;
  const int samples = argc > 4 ? std::stoi(argv[4]) : 3;
  const double size_mm = argc > 5 ? std::stod(argv[5]) : 4.0;
  const double camera_per_map = camera_dpi / maps_dpi;
  const int per_map = static_cast<int>(std::lround(camera_per_map));
  if (samples < 1 || samples > 32 || per_map < 1 || std::abs(camera_per_map - per_map) > 1e-6 || !(size_mm > 0.0)) {
    std::fprintf(stderr, "SAMPLES must be 1..32, CAMERA_DPI a whole multiple of MAPS_DPI, SIZE_MM > 0\n");
    return 2;
  }
  // The maps' grid, then the scene `samples * per_map` times finer, tiling each map pixel.
  synthetic::SceneOptions maps;
  maps.pitch_mm = 25.4 / maps_dpi;
  maps.width = maps.height = std::max(1, static_cast<int>(std::lround(size_mm / maps.pitch_mm)));
  const int per_map_samples = samples * per_map;
  const synthetic::SceneTruth fine =
      synthetic::MakeScene(scene_name, synthetic::OversampledSceneOptions(maps, per_map_samples));
  std::printf("%s, %.1f x %.1f mm, %d x %d samples (%.0f dpi)\n", scene_name.c_str(), maps.width * maps.pitch_mm,
              maps.height * maps.pitch_mm, fine.normal.width(), fine.normal.height(), camera_dpi * samples);
  Print("scene", 1, camera_dpi * samples, TallyFootprints(fine, 1));
  Print("camera pixel", samples, camera_dpi, TallyFootprints(fine, samples));
  Print("map pixel", per_map_samples, maps_dpi, TallyFootprints(fine, per_map_samples));
  return 0;
}
