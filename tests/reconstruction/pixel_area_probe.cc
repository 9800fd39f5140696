// Pixel-area probe (not a test, not run by ctest, not in the default build): how much of the
// photometric-stereo normal error on a fabric comes from where the camera's pixels fall against
// the finished map's grid, with everything else ideal (distant lights known exactly, no noise, no
// cast shadows, no lens).
//
// The scene is made 6x finer than the 300 dpi output grid; every fine pixel is shaded with the
// Principled BRDF the renderer uses (EvaluateModel, the scene's fibre frame), view straight down.
// A camera pixel is the mean of the fine pixels under it: k camera pixels per output pixel along
// each axis (k = 1, 2 or 3), its lattice shifted by `offset` camera pixels along x and y (rounded to
// the fine grid: steps of k/6). The camera images are resampled onto the output grid as the
// pipeline does (RectifyImage: pre-filter, then bicubic), then photometric stereo, against the
// truth the synthetic scanner writes (AreaAverageScene). Prints the mean / median / p95 normal
// error over the interior for robust + Burley (the presets' solver) and least squares + Lambert.
//
// Build and run:
//   cmake --build build --target reconstruction_pixel_area_probe
//   build/tests/reconstruction/reconstruction_pixel_area_probe SCENE [K] [OFFSET_PX] [FILTER] [SIZE] [SHADING]
// SHADING (Shading below) replaces the BRDF by simpler ones, to tell the causes of the on-grid
// floor apart (docs/reconstruction.md, "Photometric stereo at the camera's resolution").
// FILTER: footprint (the pipeline's, capture/rectification.h), nyquist (the Gaussian it replaced,
// sigma = 0.5 sqrt(k^2 - 1) camera px from k > 1.5 on) or none. Figures in docs/reconstruction.md.
#include <opencv2/imgproc.hpp>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <utility>
#include <vector>

#include "capture/opencv_bridge.h"
#include "capture/rectification.h"
#include "core/logging.h"
#include "core/parallel.h"
#include "core/principled_brdf.h"
#include "datasets_synthetic/renderer.h"
#include "datasets_synthetic/rig.h"
#include "datasets_synthetic/scene.h"
#include "reconstruction/photometric_stereo.h"

using namespace u3mscan;

namespace {

constexpr int kFine = 6;    // fine pixels per output pixel along each axis
constexpr int kBorder = 4;  // output pixels left out at each edge (kernel reach, clamped borders)

// What a fine pixel reflects: the renderer's BRDF, or a simpler one to tell the floor's causes apart.
enum class Shading {
  kPrincipled,    // the scene's BRDF (EvaluateModel)
  kNoLobes,       // the same, specular and sheen 0
  kLambert,       // base colour / pi, attached shadows clamped
  kGrey,          // 0.5 everywhere, clamped: the weave's geometry only
  kLinearColour,  // base colour x cos, not clamped: only the colours' weighting of the normals
  kLinearGrey,    // 0.5 x cos, not clamped: nothing a pixel's mean cannot hold (a check: ~0)
};

bool ParseShading(const std::string& name, Shading* out) {
  static const std::pair<const char*, Shading> names[] = {
      {"principled", Shading::kPrincipled}, {"no-lobes", Shading::kNoLobes},         {"lambert", Shading::kLambert},
      {"grey", Shading::kGrey},             {"linear-colour", Shading::kLinearColour}, {"linear-grey", Shading::kLinearGrey}};
  for (const auto& [n, s] : names) {
    if (name == n) return *out = s, true;
  }
  return false;
}

// Shading of one fine pixel under light l (world, unit), view +z: f(l, v) cos(theta_l), RGB.
Vec3<float> ShadeFine(const synthetic::SceneTruth& fine, int row, int col, const Vec3<float>& l, Shading shading) {
  Vec3<float> n(fine.normal.at(0, row, col), fine.normal.at(1, row, col), fine.normal.at(2, row, col));
  n.normalize();
  const Vec3<float> fibre(fine.tangent.at(0, row, col), fine.tangent.at(1, row, col), fine.tangent.at(2, row, col));
  Vec3<float> x = fibre - n * n.dot(fibre);
  if (x.squaredNorm() < 1e-6f) x = Vec3<float>(1, 0, 0) - n * n.x();
  const Vec3<float> t = x.normalized(), b = n.cross(t), v(0, 0, 1);
  PrincipledParams<float> p;
  p.base_color = Vec3<float>(fine.base_color.at(0, row, col), fine.base_color.at(1, row, col), fine.base_color.at(2, row, col));
  p.roughness = fine.roughness.at(0, row, col);
  p.specular = fine.specular.at(0, row, col);
  p.specular_tint = fine.specular_tint.at(0, row, col);
  p.sheen = fine.sheen.at(0, row, col);
  p.sheen_tint = fine.sheen_tint.at(0, row, col);
  p.anisotropic = fine.anisotropic.at(0, row, col);
  const Vec3<float> ll(l.dot(t), l.dot(b), l.dot(n)), vl(v.dot(t), v.dot(b), v.dot(n));
  const Vec3<float> grey(0.5f, 0.5f, 0.5f);
  switch (shading) {
    case Shading::kLambert: return std::max(0.0f, ll.z()) * p.base_color / static_cast<float>(M_PI);
    case Shading::kGrey: return std::max(0.0f, ll.z()) * grey;
    case Shading::kLinearColour: return ll.z() * p.base_color;
    case Shading::kLinearGrey: return ll.z() * grey;
    case Shading::kNoLobes: p.specular = p.sheen = 0.0f; break;
    case Shading::kPrincipled: break;
  }
  return std::max(0.0f, ll.z()) * synthetic::EvaluateModel(fine.model, p, ll, vl);
}

}  // namespace

int main(int argc, char** argv) {
  SetLogLevel(LogLevel::kError);
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s SCENE [K=1|2|3] [OFFSET_PX=0.33] [footprint|nyquist|none] [SIZE=192] [SHADING=principled]\n",
                 argv[0]);
    return 2;
  }
  const std::string scene_name = argv[1];
  const int k = argc > 2 ? std::stoi(argv[2]) : 1;
  const double offset_px = argc > 3 ? std::stod(argv[3]) : 0.33;
  const std::string filter = argc > 4 ? argv[4] : "footprint";
  const int n = argc > 5 ? std::stoi(argv[5]) : 192;
  Shading shading = Shading::kPrincipled;
  const std::string shading_name = argc > 6 ? argv[6] : "principled";
  if (!ParseShading(shading_name, &shading)) {
    std::fprintf(stderr, "SHADING must be principled, no-lobes, lambert, grey, linear-colour or linear-grey\n");
    return 2;
  }
  if ((k != 1 && k != 2 && k != 3) || (filter != "footprint" && filter != "nyquist" && filter != "none") || n < 16) {
    std::fprintf(stderr, "K must be 1, 2 or 3; FILTER footprint, nyquist or none; SIZE >= 16\n");
    return 2;
  }
  const int fine_per_camera = kFine / k;
  const int shift = static_cast<int>(std::lround(offset_px * fine_per_camera));  // fine pixels
  const int m = n * k;                                                            // camera pixels a side

  synthetic::SceneOptions grid_options;
  grid_options.width = grid_options.height = n;
  const synthetic::SceneTruth fine = synthetic::MakeScene(scene_name, synthetic::OversampledSceneOptions(grid_options, kFine));
  const synthetic::SceneTruth truth = synthetic::AreaAverageScene(fine, kFine);
  const synthetic::Rig rig = synthetic::MakeRig("distant", synthetic::RigOptions{});

  Stack stack;
  stack.grid = {n, n, grid_options.pitch_mm, 0.0, 0.0};
  stack.views.push_back({"top", Eigen::Vector3d(0, 0, 1e6)});
  // The camera's sample positions on the output grid: camera pixel (u, v) covers fine pixels
  // [u * fine_per_camera + shift, ...), so output pixel centre (col + 0.5) * kFine lies at camera
  // x = ((col + 0.5) * kFine - shift) / fine_per_camera - 0.5.
  RectificationMap map;
  map.grid = stack.grid;
  map.map = Image(n, n, 2, 0.0f);
  map.out_of_view.assign(static_cast<std::size_t>(n) * n, 0);
  map.camera_px_per_grid_px = filter == "footprint" ? k : 1.0;  // 1: RectifyImage adds no filter
  map.interpolation = RectifyInterpolation::kCubic;
  for (int row = 0; row < n; ++row) {
    for (int col = 0; col < n; ++col) {
      map.map.at(0, row, col) = static_cast<float>(((col + 0.5) * kFine - shift) / fine_per_camera - 0.5);
      map.map.at(1, row, col) = static_cast<float>(((row + 0.5) * kFine - shift) / fine_per_camera - 0.5);
    }
  }
  const double nyquist_sigma = k > 1.5 ? 0.5 * std::sqrt(static_cast<double>(k * k - 1)) : 0.0;
  for (std::size_t light = 0; light < rig.lights.size(); ++light) {
    LightModel model;
    model.id = rig.lights[light].id;
    model.direction_in_world = rig.lights[light].direction.normalized();
    stack.lights.push_back(model);
    const Vec3<float> l = model.direction_in_world.cast<float>();
    Image camera(m, m, 3, 0.0f);
    const int last = kFine * n - 1;
    ParallelFor(static_cast<std::size_t>(m), [&](std::size_t begin, std::size_t end) {
      for (std::size_t v = begin; v < end; ++v) {
        for (int u = 0; u < m; ++u) {
          Vec3<float> sum = Vec3<float>::Zero();
          for (int j = 0; j < fine_per_camera; ++j) {
            for (int i = 0; i < fine_per_camera; ++i) {
              const int fr = std::min(last, static_cast<int>(v) * fine_per_camera + j + shift);
              const int fc = std::min(last, u * fine_per_camera + i + shift);
              sum += ShadeFine(fine, fr, fc, l, shading);
            }
          }
          sum /= static_cast<float>(fine_per_camera * fine_per_camera);
          for (int c = 0; c < 3; ++c) camera.at(c, static_cast<int>(v), u) = sum[c];
        }
      }
    });
    if (filter == "nyquist" && nyquist_sigma > 0.0) {
      for (int c = 0; c < 3; ++c) {
        cv::Mat plane = internal::PlaneView(camera, c), blurred;
        cv::GaussianBlur(plane, blurred, cv::Size(0, 0), nyquist_sigma, nyquist_sigma, cv::BORDER_REFLECT);
        blurred.copyTo(plane);
      }
    }
    Observation observation;
    observation.light = static_cast<int>(light);
    observation.rgb = RectifyImage(camera, map);
    stack.observations.push_back(std::move(observation));
  }

  for (const bool robust : {true, false}) {
    reconstruction::PhotometricStereoOptions options;
    options.solver = robust ? reconstruction::PsSolver::kRobust : reconstruction::PsSolver::kLeastSquares;
    options.diffuse_model = robust ? reconstruction::DiffuseModel::kBurley : reconstruction::DiffuseModel::kLambert;
    const reconstruction::PhotometricStereoResult result = reconstruction::RunPhotometricStereo(stack, options);
    std::vector<double> errors;
    for (int row = kBorder; row < n - kBorder; ++row) {
      for (int col = kBorder; col < n - kBorder; ++col) {
        const Eigen::Vector3d t(truth.normal.at(0, row, col), truth.normal.at(1, row, col), truth.normal.at(2, row, col));
        const Eigen::Vector3d e(result.normal.at(0, row, col), result.normal.at(1, row, col), result.normal.at(2, row, col));
        errors.push_back(std::atan2(t.normalized().cross(e.normalized()).norm(), t.normalized().dot(e.normalized())) * 180.0 / M_PI);
      }
    }
    double mean = 0.0;
    for (double e : errors) mean += e;
    mean /= static_cast<double>(errors.size());
    std::sort(errors.begin(), errors.end());
    std::printf("%s (%s shading), %d camera px per map px, offset %.3f camera px, %s filter, %s: normal error mean %.2f median %.2f p95 %.2f deg\n",
                scene_name.c_str(), shading_name.c_str(), k, static_cast<double>(shift) / fine_per_camera, filter.c_str(),
                robust ? "robust + Burley" : "least squares + Lambert", mean, errors[errors.size() / 2],
                errors[errors.size() * 95 / 100]);
  }
  return 0;
}
