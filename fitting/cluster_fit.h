#pragma once
// One cluster's fit of the shared Principled parameters (docs/fitting.md, "Clusters" and
// "Observability"), used by FitClusterModel (principled_fit.cc) for every cluster fit and refit:
// a coarse grid start (grid_start.h), a robust Ceres solve of the cluster's sampled pixels, the
// anisotropy rotation search, the observability decision from the Fisher information and a refit
// without what it leaves out. Internal to fitting/ (not a public header of the module).

#include <Eigen/Core>
#include <cstddef>
#include <span>
#include <vector>

#include "core/principled_brdf.h"
#include "fitting/brdf_cost.h"
#include "fitting/principled_fit.h"

namespace u3mscan::fitting {

// The sampled pixels of one cluster, in one owned buffer (Ceres references it while solving).
struct ClusterSamples {
  double rotation_deg = 0.0;  // the tangent's turn the observations are expressed in (shading_frame.h)
  std::vector<LocalObservation> observations;
  std::vector<std::size_t> offsets;  // pixel p: observations[offsets[p], offsets[p + 1])
  std::vector<double> luminance_start;
  std::size_t pixels() const { return offsets.empty() ? 0 : offsets.size() - 1; }
  std::span<const LocalObservation> pixel(std::size_t p) const {
    return {observations.data() + offsets[p], offsets[p + 1] - offsets[p]};
  }
};

// The parameters `options` let the fit estimate (roughness and specular always; the tints, sheen,
// anisotropic and metallic as the options say).
ParameterMask Candidates(const FitOptions& options);

// Relative RMS residual above which a cluster counts as poorly explained: the option, or twice
// the relative noise the options declare, whichever is larger (noise alone is not a mismatch).
double MismatchThreshold(const FitOptions& options);

// Luminance with the Principled tint weights (core/principled_brdf.h, brdf::TintLuminance).
inline double Luminance(const Eigen::Vector3d& c) { return brdf::TintLuminance(c); }

// Smallest luminance to start the base-colour luminance passes from.
inline constexpr double kMinStartLuminance = 1e-3;

// The cost settings of one pixel's observations at `params`: the options' robust loss, the base
// colour's luminance passes started from `luminance_start` (at least kMinStartLuminance), as many
// passes as a tint in `params` / `free` needs (LuminancePassesFor).
PixelCostSettings CostSettingsFor(const FitOptions& options, const ParameterVector& params, const ParameterMask& free,
                                  double luminance_start);

// The whole fit of one cluster: grid start, solve, anisotropy rotation (when `search_rotation`;
// otherwise the samples' own), observability, refit. `candidates`: the parameters it may estimate
// (Candidates(options), less any the maps as a whole leave out or hold); the others stay at their
// value in `held` (DefaultParameters() but for what the maps hold) from the grid start on, so that
// what the cluster fits belongs with them. The samples may come back turned.
// `*observability_s` accumulates the seconds the observability step took.
ClusterFit FitCluster(int id, ClusterSamples& samples, const FitOptions& options, const ParameterMask& candidates,
                      const ParameterVector& held, bool search_rotation, double* observability_s);

// Share of the cluster's samples with at least one usable observation in which the fitted specular
// lobe (the prediction minus the prediction at specular 0, same base colour) carries at least
// `options.highlight_lobe_fraction` of the predicted luminance: how many pixels actually saw a
// highlight the fit could measure specular and roughness on.
double HighlightShare(const ClusterSamples& samples, const ParameterVector& params, const ParameterMask& free,
                      const FitOptions& options);

}  // namespace u3mscan::fitting
