// Accuracy probe (not a test, not run by ctest): the synthetic scanner's rigs -> capture folder ->
// calibration and rectification (pipeline stages) -> photometric stereo, compared with the scene's
// true normals. Prints, per rig and solver, the normal angular error over the interior of the map,
// the mean confidence and albedo, and the ill-conditioned pixel count. Figures in
// docs/reconstruction.md. Run: build/tests/reconstruction/reconstruction_presets_probe [RIG]
// (captures are written once under /tmp/u3mscan_presets_probe).
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <numbers>
#include <string>
#include <vector>

#include "core/logging.h"
#include "datasets_synthetic/capture_writer.h"
#include "datasets_synthetic/rig.h"
#include "pipeline/stages.h"

using namespace u3mscan;
namespace fs = std::filesystem;

namespace {

// Bumps z = a sin(kx) sin(ky) with uniform Principled parameters (roughness 0.6, specular 0.5).
synthetic::SceneTruth BumpScene(int width, int height, double pitch_mm, double amplitude_mm, double period_mm) {
  synthetic::SceneTruth scene;
  scene.name = "bumps";
  scene.pitch_mm = pitch_mm;
  auto plane = [&](int channels, float value) { return Image(width, height, channels, value, pitch_mm); };
  scene.height_mm = plane(1, 0.0f);
  scene.normal = plane(3, 0.0f);
  const double k = 2.0 * std::numbers::pi / period_mm;
  for (int row = 0; row < height; ++row)
    for (int col = 0; col < width; ++col) {
      const double x = (col + 0.5) * pitch_mm, y = -(row + 0.5) * pitch_mm;  // rows grow with -y
      scene.height_mm.at(0, row, col) = static_cast<float>(amplitude_mm * std::sin(k * x) * std::sin(k * y));
      const Eigen::Vector3d n = Eigen::Vector3d(-amplitude_mm * k * std::cos(k * x) * std::sin(k * y),
                                                -amplitude_mm * k * std::sin(k * x) * std::cos(k * y), 1.0)
                                    .normalized();
      for (int c = 0; c < 3; ++c) scene.normal.at(c, row, col) = static_cast<float>(n(c));
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

}  // namespace

int main(int argc, char** argv) {
  SetLogLevel(LogLevel::kError);
  const fs::path root = fs::temp_directory_path() / "u3mscan_presets_probe";
  synthetic::RigOptions rig_options;
  rig_options.width = 96;
  rig_options.height = 96;
  // Bumps of 0.05 mm over 1.5 mm (tilt up to 12 deg), Principled with roughness 0.6, specular 0.5.
  const auto scene = BumpScene(80, 80, rig_options.pitch_mm, 0.05, 1.5);
  for (const std::string& rig_name : synthetic::RigNames()) {
    if (argc > 1 && rig_name != argv[1]) continue;
    const fs::path dir = root / rig_name;
    if (!fs::exists(dir)) {
      synthetic::CaptureOptions capture_options;
      capture_options.format = synthetic::FrameFormat::kTiff;
      synthetic::WriteSyntheticCapture(scene, synthetic::MakeRig(rig_name, rig_options), capture_options, dir);
    }
    for (const char* solver : {"ls", "robust"}) {
      StageOptions stages = OptionsForPreset(Preset::kBalanced);
      stages.photometric_stereo.solver = reconstruction::ParsePsSolver(solver);
      RunReport report;
      PreparedCapture prepared = PrepareCapture(dir / "capture", stages, &report);
      const Stack stack = BuildSideStack(prepared, "front", stages, &report);
      const SideReconstruction rec = ReconstructSide(stack, stages, Image(), &report);
      const auto& ps = rec.photometric_stereo;
      std::vector<double> errors;
      double confidence = 0.0, albedo[3] = {0, 0, 0};
      for (int r = 0; r < stack.grid.height; ++r)
        for (int c = 0; c < stack.grid.width; ++c) {
          // The scene is centred on the world origin (datasets_synthetic/renderer.h).
          const Eigen::Vector3d p = stack.grid.PixelCentreInWorld(c, r);
          const int col = static_cast<int>(std::lround(p.x() / scene.pitch_mm + scene.normal.width() / 2.0 - 0.5));
          const int row = static_cast<int>(std::lround(scene.normal.height() / 2.0 - 0.5 - p.y() / scene.pitch_mm));
          if (col < 2 || row < 2 || col >= scene.normal.width() - 2 || row >= scene.normal.height() - 2) continue;
          const Eigen::Vector3d t(scene.normal.at(0, row, col), scene.normal.at(1, row, col), scene.normal.at(2, row, col));
          const Eigen::Vector3d m(ps.normal.at(0, r, c), ps.normal.at(1, r, c), ps.normal.at(2, r, c));
          errors.push_back(std::atan2(t.cross(m).norm(), t.dot(m)) * 180.0 / std::numbers::pi);
          confidence += ps.confidence.at(0, r, c);
          for (int k = 0; k < 3; ++k) albedo[k] += ps.albedo.at(k, r, c);
        }
      if (errors.empty()) continue;
      const double count = static_cast<double>(errors.size());
      double mean = 0.0;
      for (double e : errors) mean += e / count;
      std::sort(errors.begin(), errors.end());
      std::printf("%-12s %-6s %zu lights: normal error mean %.2f median %.2f p95 %.2f deg; confidence %.2f; "
                  "albedo %.3f %.3f %.3f (base colour 0.6 0.4 0.3); ill-conditioned %lld; near rounds %d\n",
                  rig_name.c_str(), solver, stack.lights.size(), mean, errors[errors.size() / 2],
                  errors[errors.size() * 95 / 100], confidence / count, albedo[0] / count, albedo[1] / count,
                  albedo[2] / count, ps.ill_conditioned_pixels, ps.near_iterations);
    }
  }
  return 0;
}
