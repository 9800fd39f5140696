#pragma once
// Rules on the cluster fits as a whole (docs/fitting.md), applied by FitClusterModel (and so by
// FitPrincipled) after every cluster has been fitted on its own: what one cluster's fit cannot see,
// because it is a property of the maps the clusters make together or of the capture.

#include <functional>
#include <vector>

#include "fitting/principled_fit.h"

namespace u3mscan::fitting {

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
void LeaveOutMapsNotKnownAsAWhole(const FitOptions& options, const std::vector<std::size_t>& cluster_weight,
                                  std::vector<ClusterFit>* clusters,
                                  const std::function<void(int id, const ParameterMask& left_out)>& refit);

}  // namespace u3mscan::fitting
