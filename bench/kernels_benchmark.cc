// Google Benchmark of the pipeline's inner kernels (not in ctest): the Principled BRDF evaluation,
// photometric stereo per megapixel and DCT integration per megapixel. Run:
//   build/bench/u3mscan_kernels_benchmark --benchmark_min_time=0.5
#include <benchmark/benchmark.h>

#include <cmath>

#include "core/principled_brdf.h"
#include "core/stack.h"
#include "reconstruction/normal_integration.h"
#include "reconstruction/photometric_stereo.h"

namespace u3mscan {
namespace {

void BM_PrincipledBrdf(benchmark::State& state) {
  PrincipledParams<double> p;
  p.sheen = 0.5;
  p.anisotropic = 0.3;
  const Vec3<double> l = Vec3<double>(0.3, 0.2, 0.93).normalized();
  Vec3<double> v = Vec3<double>(-0.1, 0.05, 0.99).normalized();
  for (auto _ : state) {
    v.x() += 1e-9;  // defeat hoisting
    benchmark::DoNotOptimize(EvaluatePrincipled(p, l, v));
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_PrincipledBrdf);

}  // namespace
}  // namespace u3mscan

BENCHMARK_MAIN();
