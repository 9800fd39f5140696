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
#include "tests/support/bump_scene.h"

using namespace u3mscan;
namespace fs = std::filesystem;

int main(int argc, char** argv) {
  SetLogLevel(LogLevel::kError);
  const fs::path root = fs::temp_directory_path() / "u3mscan_presets_probe";
  synthetic::RigOptions rig_options;
  rig_options.width = 96;
  rig_options.height = 96;
  // Bumps of 0.05 mm over 1.5 mm (tilt up to 12 deg), Principled with roughness 0.6, specular 0.5.
  const auto scene = testing::BumpScene(80, 80, rig_options.pitch_mm, 0.05, 1.5);
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
      Stack stack = BuildSideStack(prepared, "front", stages, &report);
      const SideReconstruction rec = ReconstructSide(&stack, stages, Image(), &report);
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
