#include "fitting/observability.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>

namespace u3mscan::fitting {
namespace {

using Matrix7 = Eigen::Matrix<double, kFitParameterCount, kFitParameterCount>;

// Eigenvalues below this fraction of the largest are directions without information (rounding of
// a rank-deficient J^T J is ~1e-16 relative).
constexpr double kNullEigenvalueFraction = 1e-12;
// A parameter whose weight in a null direction exceeds this is unconstrained.
constexpr double kNullComponent = 1e-6;

double InformationScale(const ObservabilityContext& context, const ObservabilityOptions& options, int free_count) {
  const double pixels = std::max(1, context.pixel_count);
  const int dof = context.residual_count - free_count;
  const double chi2 = dof > 0 ? 2.0 * context.cost / dof : 1.0;
  return std::min(1.0, options.effective_pixels / pixels) / std::max(1.0, chi2);
}

}  // namespace

std::string LeaveOutHint(FitParameter p, const ObservabilityContext& context) {
  char buffer[200];
  switch (p) {
    case FitParameter::kSheen:
      if (context.max_grazing_weight < 0.0) {
        return "sheen acts only at grazing half-angles; it needs an oblique view with lights grazing from the "
               "opposite side";
      }
      std::snprintf(buffer, sizeof buffer,
                    "sheen acts only at grazing half-angles; it needs an oblique view with lights grazing from the "
                    "opposite side (largest Schlick weight (1-cos_d)^5 in this capture: %.4f)",
                    context.max_grazing_weight);
      return buffer;
    case FitParameter::kSheenTint:
      return "sheen tint needs measurable sheen on a coloured base";
    case FitParameter::kSpecularTint:
      return "specular tint needs measurable highlights on a coloured base";
    case FitParameter::kAnisotropic:
      return "anisotropy needs highlights seen from several azimuths (its direction, anisotropy_rotation, is "
             "searched per cluster unless the fit options turn that off)";
    case FitParameter::kSpecular:
    case FitParameter::kRoughness:
      return "needs lights that put highlights on the sample (and has no effect on a metal)";
    case FitParameter::kMetallic:
      return "metallic trades off against specular and base colour";
  }
  return "";
}

bool ObservabilityOptions::Check() const {
  return max_std > 0.0 && effective_pixels >= 1 && uniform_abs_tolerance >= 0.0 && uniform_sigma_factor >= 0.0 &&
         default_rejection_chi2 >= 0.0;
}

double EffectiveChi2Increase(double cost_at_fit, double cost_at_default, const ObservabilityContext& context,
                             const ObservabilityOptions& options) {
  return 2.0 * (cost_at_default - cost_at_fit) * InformationScale(context, options, 0);
}

ParameterVector PosteriorStdDev(const Matrix7& fisher, const ParameterMask& free, const ObservabilityContext& context,
                                const ObservabilityOptions& options) {
  ParameterVector out;
  out.fill(std::numeric_limits<double>::infinity());
  int index[kFitParameterCount];
  int n = 0;
  for (int i = 0; i < kFitParameterCount; ++i) {
    if (free[i]) index[n++] = i;
  }
  if (n == 0) return out;
  Eigen::MatrixXd f(n, n);
  for (int a = 0; a < n; ++a) {
    for (int b = 0; b < n; ++b) f(a, b) = fisher(index[a], index[b]);
  }
  // Systematic-error floor (no more than effective_pixels pixels' worth of information) and misfit
  // inflation (reduced chi^2 of the fit) in one factor.
  f *= InformationScale(context, options, n);

  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(f);
  if (eigen.info() != Eigen::Success) return out;
  const Eigen::VectorXd& lambda = eigen.eigenvalues();
  const Eigen::MatrixXd& v = eigen.eigenvectors();
  const double lambda_max = std::max(lambda.maxCoeff(), 0.0);
  const double null_level = kNullEigenvalueFraction * lambda_max;
  for (int a = 0; a < n; ++a) {
    double variance = 0.0;
    bool unconstrained = lambda_max <= 0.0;
    for (int j = 0; j < n && !unconstrained; ++j) {
      const double w = v(a, j) * v(a, j);
      if (lambda(j) <= null_level) {
        if (w > kNullComponent) unconstrained = true;
      } else {
        variance += w / lambda(j);
      }
    }
    if (!unconstrained) out[index[a]] = std::sqrt(variance);
  }
  return out;
}

Matrix7 PixelInformation(const Eigen::MatrixXd& parameter_jacobian, const Eigen::MatrixXd& normal_jacobian) {
  Matrix7 information = parameter_jacobian.transpose() * parameter_jacobian;
  if (normal_jacobian.cols() == 0) return information;
  const Eigen::Matrix2d tilt_information = normal_jacobian.transpose() * normal_jacobian;
  const Eigen::Matrix<double, 2, kFitParameterCount> cross = normal_jacobian.transpose() * parameter_jacobian;
  // Pseudo-inverse of the 2 x 2 tilt block: a direction without information takes none.
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eigen(tilt_information);
  const double lambda_max = std::max(eigen.eigenvalues().maxCoeff(), 0.0);
  for (int j = 0; j < 2; ++j) {
    const double lambda = eigen.eigenvalues()(j);
    if (!(lambda > kNullEigenvalueFraction * lambda_max) || lambda <= 0.0) continue;
    const Eigen::Matrix<double, 1, kFitParameterCount> projected = eigen.eigenvectors().col(j).transpose() * cross;
    information.noalias() -= projected.transpose() * projected / lambda;
  }
  // The Schur complement is positive semi-definite; keep it exactly symmetric against rounding.
  return 0.5 * (information + information.transpose());
}

ObservabilityDecision DecideObservability(const Matrix7& fisher, const ParameterMask& candidates,
                                          const ObservabilityContext& context, const ObservabilityOptions& options) {
  if (!options.Check()) throw std::invalid_argument("DecideObservability: invalid ObservabilityOptions");
  ObservabilityDecision out;
  out.measured = candidates;
  for (int i = 0; i < kFitParameterCount; ++i) {
    if (!candidates[i]) out.reason[i] = "held at its U3M default by the fit options";
  }
  for (;;) {
    const ParameterVector std_dev = PosteriorStdDev(fisher, out.measured, context, options);
    int worst = -1;
    double worst_ratio = 1.0;
    for (int i = 0; i < kFitParameterCount; ++i) {
      if (!out.measured[i]) continue;
      const double ratio = std_dev[i] / options.max_std;
      if (ratio > worst_ratio) {
        worst_ratio = ratio;
        worst = i;
      }
    }
    if (worst < 0) {
      for (int i = 0; i < kFitParameterCount; ++i) {
        if (out.measured[i]) out.std_dev[i] = std_dev[i];
      }
      break;
    }
    out.measured[worst] = false;
    out.std_dev[worst] = std_dev[worst];
    char buffer[160];
    if (std::isinf(std_dev[worst])) {
      std::snprintf(buffer, sizeof buffer, "not constrained by this capture (no information in the data); ");
    } else {
      std::snprintf(buffer, sizeof buffer, "not constrained by this capture (posterior std %.3g > %.3g); ",
                    std_dev[worst], options.max_std);
    }
    out.reason[worst] = buffer + LeaveOutHint(static_cast<FitParameter>(worst), context);
  }
  for (int i = 0; i < kFitParameterCount; ++i) {
    if (!candidates[i]) out.std_dev[i] = std::numeric_limits<double>::infinity();
  }
  return out;
}

bool IsUniformWithinNoise(double map_std, double pooled_std_dev, const ObservabilityOptions& options) {
  const double tolerance = std::max(options.uniform_abs_tolerance,
                                    std::isfinite(pooled_std_dev) ? options.uniform_sigma_factor * pooled_std_dev : 0.0);
  return map_std <= tolerance;
}

}  // namespace u3mscan::fitting
