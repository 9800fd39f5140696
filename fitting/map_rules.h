#pragma once
// Rules on the cluster fits as a whole (docs/fitting.md), applied by FitClusterModel (and so by
// FitPrincipled) after every cluster has been fitted on its own: what one cluster's fit cannot see,
// because it is a property of the maps the clusters make together or of the capture.

#include <array>
#include <functional>
#include <string>
#include <vector>

#include "fitting/principled_fit.h"

namespace u3mscan::fitting {

// False for a cluster the model does not explain (relative RMS residual above
// unusable_relative_rms): FitClusterModel leaves it out whole, its pixels keep the defaults, and
// no rule over the clusters counts it or fits it again.
bool Usable(const FitOptions& options, const ClusterFit& cluster);

// Hidden-lobe rule (docs/fitting.md), applied by FitPrincipled / FitClusterModel after the cluster
// fits: a cluster whose roughness ended at the fit's lower bound (<= 0.032, GGX's alpha clamp)
// while specular was left out (held at its U3M default 0.5) hid the held lobe by shrinking it to a
// spike between the lights; unless the capture has saturated highlights (which can pin such a
// spike, the mirror-like case), that roughness is no measurement and is left out with the reason.
// Returns the ids of the clusters changed.
std::vector<int> LeaveOutHiddenLobeRoughness(bool capture_saturated, std::vector<ClusterFit>* clusters);

// Rule of the maps as a whole (docs/fitting.md), applied by FitPrincipled / FitClusterModel after
// the cluster fits: a parameter whose posterior std pooled over the clusters that measure it (RMS
// weighted by `cluster_weight[id]`, their pixels; clusters above unusable_relative_rms do not
// count) exceeds observability.max_std is left out of every cluster (value the U3M default, std
// inf, the reason). Each usable cluster that measured it is first handed to `refit(id, left_out)`,
// which must fit that cluster again with every parameter in `left_out` held at its default, so that
// the values it keeps explain the data with the default the maps will hold. Repeats until the
// pooled stds of what is left pass. Clusters are indexed by their id; `refit` runs in parallel.
// Returns the parameters it left out.
ParameterMask LeaveOutMapsNotKnownAsAWhole(const FitOptions& options, const std::vector<std::size_t>& cluster_weight,
                                           std::vector<ClusterFit>* clusters,
                                           const std::function<void(int id, const ParameterMask& left_out)>& refit);

// True when the per-pixel step refines `parameter` (FitMode::kPerPixel: roughness, and specular
// with refine_specular_per_pixel): its map is then more than its clusters' values.
bool RefinedPerPixel(const FitOptions& options, FitParameter parameter);

// Uniform verdict on the cluster-valued maps (docs/fitting.md, "Uniform within noise"), applied by
// FitClusterModel after the rule of the maps as a whole. The map of a parameter the per-pixel step
// does not refine holds its clusters' values in the maps (a cluster's own where it measured it, the
// U3M default where not). When those of the usable clusters (weighted by `cluster_weight[id]`)
// spread no more than IsUniformWithinNoise allows for the std pooled over the clusters that
// measured it, the map is written as one constant, their weighted mean. Each usable cluster whose
// value in the maps is farther than observability.uniform_abs_tolerance from the mean is first
// handed to `refit(id, held, values)`, which must fit it again with every parameter in `held` fixed
// at its entry of `values`, so that what the cluster keeps explains the data with the value the map
// holds; then every usable cluster holds the mean as its value, its estimate otherwise as before
// the hold (measured or not, std, reason, reliability). Repeats while the refits leave another map
// uniform. Returns, per parameter, the reason of the verdict ("" where none was made here): a
// cluster's value of a parameter with a verdict is its pixels' value in the maps even where it did
// not measure it. Clusters are indexed by their id; `refit` runs in parallel.
std::array<std::string, kFitParameterCount> HoldUniformClusterMaps(
    const FitOptions& options, const std::vector<std::size_t>& cluster_weight, std::vector<ClusterFit>* clusters,
    const std::function<void(int id, const ParameterMask& held, const ParameterVector& values)>& refit);

}  // namespace u3mscan::fitting
