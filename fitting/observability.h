#pragma once
// Observability: which Principled parameters does a capture constrain?
//
// From the Fisher information F = J^T J of a cluster fit (J: Jacobian of the weighted residuals,
// i.e. in units of the noise sigma, one column per FitParameter) the posterior standard deviation
// of each free parameter is sqrt((F^-1)_ii), with the other free parameters marginalised. Two
// corrections keep this honest on real captures:
//   - systematic error (normals, calibration, model) does not average down with the number of
//     pixels: F is scaled to at most `effective_pixels` pixels' worth of information;
//   - a poor fit inflates the uncertainty: the covariance is multiplied by max(1, reduced chi^2).
//   - the normals are estimates too (photometric stereo, then refined with the fit), so each
//     sample pixel's two normal tilts are marginalised out of its information (Schur complement,
//     PixelInformation below): a lobe that a small tilt of the normal imitates, such as a weak
//     broad highlight over a pixel that averages the facets of a yarn's flank, is not claimed as
//     measured.
// A direction of F that carries no information (a parameter without effect, or two that trade
// off exactly, e.g. specular_tint on a grey base) gives an infinite deviation.
//
// Rule: starting from all candidate parameters, the one with the largest std / max_std is left out
// while that ratio exceeds 1, and the deviations are recomputed without it. Left-out parameters are
// written as their U3M default with no texture and reported "not measured" with the reason,
// unless the data exclude the default (default_rejection_chi2 below).

#include <Eigen/Core>
#include <array>
#include <string>

#include "fitting/brdf_cost.h"

namespace u3mscan::fitting {

struct ObservabilityOptions {
  // Largest posterior standard deviation (parameter units, all in [0, 1]) at which a parameter
  // counts as measured.
  double max_std = 0.05;
  // Pixels' worth of information at most (systematic-error floor, see above).
  int effective_pixels = 16;
  // A measured map whose spread over the pixels is below max(uniform_abs_tolerance,
  // uniform_sigma_factor * its pooled uncertainty) is reported as a constant.
  double uniform_abs_tolerance = 0.01;
  double uniform_sigma_factor = 2.0;
  // A parameter the rule would leave out is kept after all when setting it to its U3M default
  // raises chi^2 (with the same effective-pixel scaling) by more than this: the data do not pin it
  // down, but they exclude the default (e.g. roughness of a mirror-like sample whose highlights all
  // fall between the lights or saturate).
  double default_rejection_chi2 = 9.0;
  // Marginalise each sample pixel's normal tilts (see above). Off treats the normals as exact,
  // which claims too much on woven fabrics (docs/fitting.md "Woven scenes on honest captures").
  bool marginalise_normals = true;

  bool Check() const;
};

// What the capture tells about the parameters of one cluster.
struct ObservabilityDecision {
  ParameterMask measured{};    // constrained well enough to be fitted
  ParameterVector std_dev{};   // posterior standard deviation (inf when unconstrained)
  std::array<std::string, kFitParameterCount> reason;  // why a parameter was left out ("" if measured)
};

// Context for readable reasons.
struct ObservabilityContext {
  int pixel_count = 0;            // pixels whose Jacobians were summed into the Fisher matrix
  int residual_count = 0;         // rows of the stacked Jacobian
  double cost = 0.0;              // 0.5 * sum of squared weighted residuals at the solution
  double max_grazing_weight = 0;  // largest (1 - cos_d)^5 over the cluster's observations
};

// Why a parameter could not be measured, for the reason text: what kind of capture it needs. A
// negative context.max_grazing_weight leaves out the figure of the capture's most grazing observation.
std::string LeaveOutHint(FitParameter parameter, const ObservabilityContext& context);

// Posterior standard deviations of the `free` parameters from a Fisher matrix (7 x 7) in the
// corrected form described above; parameters not free get inf. Uses an eigen-decomposition so that
// exactly degenerate directions show up as inf instead of as huge numbers from rounding.
ParameterVector PosteriorStdDev(const Eigen::Matrix<double, kFitParameterCount, kFitParameterCount>& fisher,
                                const ParameterMask& free, const ObservabilityContext& context,
                                const ObservabilityOptions& options);

// One pixel's Fisher information about the 7 parameters, J^T J of its weighted residuals
// (`parameter_jacobian`, 3n x 7), with the information its normal's two tilts take
// (`normal_jacobian`, 3n x 2; may be empty) marginalised out:
//   J^T J - J^T Jn (Jn^T Jn)^+ Jn^T J.
// A tilt direction without information (Jn^T Jn singular) takes none.
Eigen::Matrix<double, kFitParameterCount, kFitParameterCount> PixelInformation(
    const Eigen::MatrixXd& parameter_jacobian, const Eigen::MatrixXd& normal_jacobian);

// The iterative leave-out rule over `candidates` (parameters the options let the fit estimate;
// the others are reported as "held at the default by the options").
ObservabilityDecision DecideObservability(
    const Eigen::Matrix<double, kFitParameterCount, kFitParameterCount>& fisher, const ParameterMask& candidates,
    const ObservabilityContext& context, const ObservabilityOptions& options);

// Chi^2 increase, in the corrected units above, of moving from a solution of cost `cost_at_fit`
// to one of cost `cost_at_default` (both 0.5 * sum of squared weighted residuals).
double EffectiveChi2Increase(double cost_at_fit, double cost_at_default, const ObservabilityContext& context,
                             const ObservabilityOptions& options);

// True when a measured map of standard deviation `map_std` over its pixels is uniform within its
// pooled uncertainty (see ObservabilityOptions).
bool IsUniformWithinNoise(double map_std, double pooled_std_dev, const ObservabilityOptions& options);

}  // namespace u3mscan::fitting
