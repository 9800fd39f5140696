// Google Benchmark of the pipeline's inner kernels (not in ctest): the Principled BRDF evaluation,
// photometric stereo per megapixel (ls and robust, 16 distant lights), normal integration per
// megapixel (DCT and robust) and the Principled fit (clusters, then every pixel's normal and
// colour) on a glossy bump field. Items processed = pixels, so Google Benchmark prints pixels/s;
// wall-clock based (UseRealTime), since the kernels run on ParallelFor worker threads.
//   build/bench/u3mscan_kernels_benchmark --benchmark_min_time=0.5
#include <benchmark/benchmark.h>

#include <cmath>
#include <cstdio>

#include "core/principled_brdf.h"
#include "core/stack.h"
#include "fitting/principled_fit.h"
#include "fitting/shading_frame.h"
#include "reconstruction/normal_integration.h"
#include "reconstruction/photometric_stereo.h"

namespace u3mscan {
namespace {

constexpr double kPitchMm = 25.4 / 300.0;

void BM_PrincipledBrdf(benchmark::State& state) {
  PrincipledParams<double> p;
  p.sheen = 0.5;
  p.anisotropic = 0.3;
  const Vec3<double> l = Vec3<double>(0.3, 0.2, 0.93).normalized();
  Vec3<double> v = Vec3<double>(-0.1, 0.05, 0.99).normalized();
  for (auto _ : state) {
    benchmark::DoNotOptimize(v);
    benchmark::DoNotOptimize(EvaluatePrincipled(p, l, v));
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_PrincipledBrdf);

// The bump field's normal at a pixel: slopes up to 0.3.
Eigen::Vector3d BumpNormal(int col, int row) {
  const double gx = 0.3 * std::sin(0.2 * col), gy = 0.3 * std::cos(0.17 * row);
  return Eigen::Vector3d(-gx, -gy, 1.0).normalized();
}

// A bumpy surface under 16 distant lights (rings at 30 and 60 deg), seen from 300 mm above,
// noise-free: Lambertian (`glossy` false), or a Principled material with roughness 0.4 and
// specular 0.5 rendered in the fit's own shading frame.
Stack MakeStack(int side, bool glossy = false) {
  Stack stack;
  stack.grid.width = stack.grid.height = side;
  stack.grid.pitch_mm = kPitchMm;
  stack.grid.x0_mm = -0.5 * side * kPitchMm;  // centred under the camera
  stack.grid.y1_mm = 0.5 * side * kPitchMm;
  stack.views.push_back({});
  for (int k = 0; k < 16; ++k) {
    const double elevation = (k < 8 ? 30.0 : 60.0) * M_PI / 180.0, azimuth = (45.0 * k + (k < 8 ? 0 : 22.5)) * M_PI / 180.0;
    LightModel light;
    char id[8];
    std::snprintf(id, sizeof id, "L%02d", k);  // (not "L" + to_string: GCC 12 -Wrestrict false positive)
    light.id = id;
    light.direction_in_world = {std::cos(elevation) * std::cos(azimuth), std::cos(elevation) * std::sin(azimuth), std::sin(elevation)};
    stack.lights.push_back(light);
  }
  stack.views.front().centre_in_world_mm = Eigen::Vector3d(0.0, 0.0, 300.0);
  PrincipledParams<double> material;
  material.base_color = Vec3<double>(0.6, 0.45, 0.3);
  material.roughness = 0.4;
  material.specular = 0.5;
  for (int k = 0; k < 16; ++k) {
    Observation o;
    o.light = k;
    o.rgb = Image(side, side, 3, 0.0f, kPitchMm);
    const Eigen::Vector3d& l = stack.lights[k].direction_in_world;
    for (int row = 0; row < side; ++row) {
      for (int col = 0; col < side; ++col) {
        const Eigen::Vector3d n = BumpNormal(col, row);
        if (!glossy) {
          const float shade = static_cast<float>(std::max(0.0, n.dot(l)) * 0.6 / M_PI);
          for (int c = 0; c < 3; ++c) o.rgb.at(c, row, col) = shade;
          continue;
        }
        const fitting::ShadingFrame frame = fitting::MakeShadingFrame(n);
        const Eigen::Vector3d point = stack.grid.PixelCentreInWorld(col, row, 0.0);
        const Eigen::Vector3d v = (stack.views.front().centre_in_world_mm - point).normalized();
        const Eigen::Vector3d l_local = frame.ToLocal(l), v_local = frame.ToLocal(v);
        const Vec3<double> f = EvaluatePrincipled(material, Vec3<double>(l_local), Vec3<double>(v_local));
        for (int c = 0; c < 3; ++c) o.rgb.at(c, row, col) = static_cast<float>(f(c) * std::max(0.0, l_local.z()));
      }
    }
    stack.observations.push_back(std::move(o));
  }
  return stack;
}

// Args: side, robust (0: least squares), glossy (0: Lambertian). On the glossy stack the solver
// estimates a Burley roughness and runs its re-weighting rounds, as on a fabric; on the
// Lambertian one it keeps Lambert's law (one round).
void BM_PhotometricStereo(benchmark::State& state) {
  const int side = static_cast<int>(state.range(0));
  const bool glossy = state.range(2) != 0;
  const Stack stack = MakeStack(side, glossy);
  reconstruction::PhotometricStereoOptions options;
  options.solver = state.range(1) ? reconstruction::PsSolver::kRobust : reconstruction::PsSolver::kLeastSquares;
  for (auto _ : state) benchmark::DoNotOptimize(reconstruction::RunPhotometricStereo(stack, options));
  state.SetItemsProcessed(state.iterations() * side * side);
  state.SetLabel(std::string(options.solver == reconstruction::PsSolver::kRobust ? "robust" : "ls") + ", 16 lights" +
                 (glossy ? ", glossy (Burley rounds)" : ", Lambertian"));
}
BENCHMARK(BM_PhotometricStereo)
    ->Args({256, 0, 0})
    ->Args({256, 1, 0})
    ->Args({1024, 0, 0})
    ->Args({1024, 1, 0})
    ->Args({256, 1, 1})
    ->Args({1024, 1, 1})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

void BM_Integration(benchmark::State& state) {
  const int side = static_cast<int>(state.range(0));
  Image normal(side, side, 3, 0.0f, kPitchMm);
  for (int row = 0; row < side; ++row) {
    for (int col = 0; col < side; ++col) {
      const double gx = 0.3 * std::sin(0.2 * col), gy = 0.3 * std::cos(0.17 * row);
      const Eigen::Vector3d n = Eigen::Vector3d(-gx, -gy, 1.0).normalized();
      for (int c = 0; c < 3; ++c) normal.at(c, row, col) = static_cast<float>(n[c]);
    }
  }
  reconstruction::IntegrationOptions options;
  options.pitch_mm = kPitchMm;
  options.method = state.range(1) ? reconstruction::Integrator::kRobust : reconstruction::Integrator::kDct;
  for (auto _ : state) benchmark::DoNotOptimize(reconstruction::IntegrateNormals(normal, Image(), options));
  state.SetItemsProcessed(state.iterations() * side * side);
  state.SetLabel(reconstruction::IntegratorName(options.method));
}
BENCHMARK(BM_Integration)->Args({256, 0})->Args({1024, 0})->Args({256, 1})->Args({1024, 1})->Unit(benchmark::kMillisecond)->UseRealTime();

// The fit of `FitPrincipled` with its default options (clusters, observability, then every pixel's
// normal refined and its colour solved) on the glossy bump field, started from the true normals.
void BM_FitPrincipled(benchmark::State& state) {
  const int side = static_cast<int>(state.range(0));
  const Stack stack = MakeStack(side, /*glossy=*/true);
  fitting::SurfaceGeometry geometry;
  geometry.normals = Image(side, side, 3, 0.0f, kPitchMm);
  for (int row = 0; row < side; ++row) {
    for (int col = 0; col < side; ++col) {
      const Eigen::Vector3d n = BumpNormal(col, row);
      for (int c = 0; c < 3; ++c) geometry.normals.at(c, row, col) = static_cast<float>(n(c));
    }
  }
  const fitting::FitOptions options;
  for (auto _ : state) benchmark::DoNotOptimize(fitting::FitPrincipled(stack, geometry, options));
  state.SetItemsProcessed(state.iterations() * side * side);
  state.SetLabel("16 lights, roughness 0.4, specular 0.5");
}
BENCHMARK(BM_FitPrincipled)->Arg(128)->Arg(256)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
}  // namespace u3mscan

BENCHMARK_MAIN();
