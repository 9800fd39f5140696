#pragma once
// Coarse grid start of a cluster fit (docs/fitting.md, "Initialisation"): the Levenberg-Marquardt
// solve starts from the best point of a fixed grid over roughness, specular and sheen, not from
// luck. Tints, anisotropic and metallic start at 0, where the model is linear in the base colour.

#include <functional>

#include "fitting/brdf_cost.h"

namespace u3mscan::fitting {

// The grid's smallest roughness, above sqrt(kMinAlpha) = 0.032 where GGX's alpha clamp would zero
// its derivative. A solve that ends below it went past every start toward the bound.
inline constexpr double kSmallestStartRoughness = 0.05;

// The grid point of least `cost`. A parameter outside `candidates` takes no grid: it stays at its
// value in `held` at every point (a refit with a parameter held by the maps must fit the others
// with it, from the start on). Sheen is searched only when `search_sheen` (the capture has grazing
// observations); otherwise a candidate sheen starts at 0. Roughness grid points below
// `min_roughness` are skipped.
ParameterVector GridStart(const ParameterMask& candidates, const ParameterVector& held, bool search_sheen,
                          const std::function<double(const ParameterVector&)>& cost, double min_roughness = 0.0);

}  // namespace u3mscan::fitting
