// Google Benchmark of the reconstruction kernels (not a test; not run by ctest). Built when the
// benchmark package is found:
//   build/tests/reconstruction/reconstruction_benchmark --benchmark_filter=Integrate
// Items per second = pixels per second.
#include <benchmark/benchmark.h>

#include "reconstruction/normal_integration.h"
#include "reconstruction/photometric_stereo.h"
#include "render_stack.h"

namespace u3mscan::reconstruction {
namespace {

using namespace testing;  // NOLINT: the render helpers

constexpr double kPitchMm = 25.4 / 600.0;

HeightField BenchSurface() { return Bumps(0.1, 2.0); }

Image BenchNormals(int size, const HeightField& s) {
  const MetricGrid grid = Grid(size, size, kPitchMm);
  Image n(size, size, 3, 0.0f, kPitchMm);
  for (int r = 0; r < size; ++r)
    for (int c = 0; c < size; ++c) {
      const Eigen::Vector3d p = grid.PixelCentreInWorld(c, r);
      const Eigen::Vector3d v = s.Normal(p.x(), p.y());
      for (int k = 0; k < 3; ++k) n.at(k, r, c) = static_cast<float>(v(k));
    }
  return n;
}

void BM_PhotometricStereo(benchmark::State& state, PsSolver solver, bool near) {
  const int size = static_cast<int>(state.range(0));
  const MetricGrid grid = Grid(size, size, kPitchMm);
  const auto point = [](double a, double e) { return Point(a, e, 300.0, 1.0); };
  const Stack stack = near ? RenderStack(grid, Ring(8, 35.0, 60.0, point), BenchSurface())
                           : RenderStack(grid, Ring(8, 35.0, 60.0, Directional), BenchSurface());
  PhotometricStereoOptions options;
  options.solver = solver;
  for (auto _ : state) benchmark::DoNotOptimize(RunPhotometricStereo(stack, options));
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(size) * size);
}
BENCHMARK_CAPTURE(BM_PhotometricStereo, ls_distant, PsSolver::kLeastSquares, false)->Arg(256)->Arg(1024)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_PhotometricStereo, robust_distant, PsSolver::kRobust, false)->Arg(256)->Arg(1024)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_PhotometricStereo, robust_near, PsSolver::kRobust, true)->Arg(256)->Arg(1024)->Unit(benchmark::kMillisecond);

// A tear: z = k atan2 around a point near the left border; not integrable, the robust
// integrator has to find the cut.
HeightField Tear(int size) {
  const double xc = -0.3 * size * kPitchMm, yc = 0.0, k = 0.05;  // yc on a row boundary
  return {[=](double x, double y) { return k * std::atan2(y - yc, x - xc); },
          [=](double x, double y) { return -k * (y - yc) / ((x - xc) * (x - xc) + (y - yc) * (y - yc)); },
          [=](double x, double y) { return k * (x - xc) / ((x - xc) * (x - xc) + (y - yc) * (y - yc)); }};
}

void BM_Integrate(benchmark::State& state, Integrator method, bool tear) {
  const int size = static_cast<int>(state.range(0));
  const Image normals = BenchNormals(size, tear ? Tear(size) : BenchSurface());
  IntegrationOptions options;
  options.method = method;
  for (auto _ : state) benchmark::DoNotOptimize(IntegrateNormals(normals, Image(), options));
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(size) * size);
}
// The weighted DCT integration of the near-light refinement (confidence as per-pixel weight: PCG
// preconditioned by the DCT Poisson solve) at an awkward size: a quarter of the 36 MP grid,
// 1380 x 921 = (2^2 3 5 23) x (3 307), whose line lengths have prime factors above 13 (args:
// width, height, weighted). Weights: 1 with a band of 0.3 and a hole of 0, like a confidence map;
// weighted = 0 runs the unweighted exact DCT solve at the same size instead.
void BM_IntegrateWeighted(benchmark::State& state) {
  const int w = static_cast<int>(state.range(0)), h = static_cast<int>(state.range(1));
  const Image square = BenchNormals(std::max(w, h), BenchSurface());
  Image normals(w, h, 3, 0.0f, kPitchMm), weight(w, h, 1, 1.0f, kPitchMm);
  for (int k = 0; k < 3; ++k)
    for (int r = 0; r < h; ++r)
      for (int c = 0; c < w; ++c) normals.at(k, r, c) = square.at(k, r, c);
  for (int r = 0; r < h; ++r)
    for (int c = 0; c < w; ++c) {
      if (c > w / 3 && c < w / 3 + 40) weight.at(0, r, c) = 0.3f;
      const double dx = c - 0.7 * w, dy = r - 0.5 * h;
      if (dx * dx + dy * dy < 0.01 * w * h) weight.at(0, r, c) = 0.0f;
    }
  IntegrationOptions options;
  int iterations = 0;
  for (auto _ : state) {
    const IntegrationResult result = IntegrateNormals(normals, state.range(2) ? weight : Image(), options);
    iterations = result.cg_iterations;
    benchmark::DoNotOptimize(result);
  }
  state.counters["cg_iterations"] = iterations;
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(w) * h);
}
BENCHMARK(BM_IntegrateWeighted)->Args({1380, 921, 1})->Args({1380, 921, 0})->Args({1024, 1024, 1})->Unit(benchmark::kMillisecond)->UseRealTime();

BENCHMARK_CAPTURE(BM_Integrate, dct, Integrator::kDct, false)->Arg(256)->Arg(1024)->Arg(2048)->Arg(6000)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Integrate, robust, Integrator::kRobust, false)->Arg(256)->Arg(1024)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Integrate, robust_tear, Integrator::kRobust, true)->Arg(256)->Arg(1024)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace u3mscan::reconstruction

BENCHMARK_MAIN();
