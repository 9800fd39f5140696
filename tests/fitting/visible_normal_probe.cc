// Visible-normal probe (not a test, not run by ctest, not in the default build): how far the normal
// a tilted camera sees in a map pixel is from the pixel's area-average normal (the truth the
// synthetic scanner writes, and the normal the fit gives every view).
//
// The scene is made FACTOR times finer than the 300 dpi output grid (OversampledSceneOptions). A
// camera tilted TILT degrees from the vertical toward -y (the oblique rig's side) sees each fine
// facet over the projected area max(0, n . v) / n_z per unit of table area, so its normal of a map
// pixel is the normalised sum of the fine normals with those weights; masking by other facets is
// left out, so this is a lower bound of the difference. Prints the mean angle between that normal
// and the area-average normal, and the mean of its component toward the camera (degrees; > 0: the
// camera sees the pixel tilted toward itself). Where the fine facets are steep below the pixel
// scale (the velvet's fibre tips), the tilted view's data belong with another normal than the top
// view's, which one normal per pixel cannot hold (docs/fitting.md, "Sheen with the oblique camera").
//
// Build and run:
//   cmake --build build --target fitting_visible_normal_probe
//   build/tests/fitting/fitting_visible_normal_probe SCENE [FACTOR] [TILT_DEG]
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <numbers>
#include <string>

#include "datasets_synthetic/scene.h"

using namespace u3mscan;

namespace {
constexpr int kGridPixels = 96;
constexpr double kPitchMm = 25.4 / 300.0;

double Degrees(double radians) { return radians * 180.0 / std::numbers::pi; }
}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s SCENE [FACTOR=6] [TILT_DEG=60]\n", argv[0]);
    return 2;
  }
  const std::string scene_name = argv[1];
  const int factor = argc > 2 ? std::atoi(argv[2]) : 6;
  const double tilt_deg = argc > 3 ? std::atof(argv[3]) : 60.0;
  if (factor < 1 || !(tilt_deg >= 0.0 && tilt_deg < 90.0)) {
    std::fprintf(stderr, "FACTOR must be >= 1 and TILT_DEG in [0, 90)\n");
    return 2;
  }
  synthetic::SceneOptions grid;
  grid.width = grid.height = kGridPixels;
  grid.pitch_mm = kPitchMm;
  const synthetic::SceneTruth fine = synthetic::MakeScene(scene_name, synthetic::OversampledSceneOptions(grid, factor));
  const double tilt = tilt_deg * std::numbers::pi / 180.0;
  const Eigen::Vector3d view(0.0, -std::sin(tilt), std::cos(tilt));  // unit, toward the camera
  double angle_sum = 0.0, toward_sum = 0.0;
  for (int row = 0; row < grid.height; ++row) {
    for (int col = 0; col < grid.width; ++col) {
      Eigen::Vector3d area = Eigen::Vector3d::Zero(), seen = Eigen::Vector3d::Zero();
      for (int i = 0; i < factor; ++i) {
        for (int j = 0; j < factor; ++j) {
          const int r = row * factor + i, c = col * factor + j;
          const Eigen::Vector3d n(fine.normal.at(0, r, c), fine.normal.at(1, r, c), fine.normal.at(2, r, c));
          area += n;
          seen += std::max(0.0, n.dot(view)) / n.z() * n;
        }
      }
      area.normalize();
      seen.normalize();
      angle_sum += Degrees(std::acos(std::clamp(area.dot(seen), -1.0, 1.0)));
      const Eigen::Vector3d toward = (view - view.dot(area) * area).normalized();  // in area's tangent plane
      toward_sum += Degrees(std::asin(std::clamp((seen - area.dot(seen) * area).dot(toward), -1.0, 1.0)));
    }
  }
  const double pixels = static_cast<double>(grid.width) * grid.height;
  std::printf("%s, %dx finer, camera %.0f deg: mean angle %.2f deg, mean tilt toward the camera %.2f deg\n",
              scene_name.c_str(), factor, tilt_deg, angle_sum / pixels, toward_sum / pixels);
  return 0;
}
