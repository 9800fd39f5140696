#include "fitting/cluster_fit.h"

#include <ceres/ceres.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>

#include "core/elapsed.h"
#include "core/logging.h"
#include "fitting/grid_start.h"
#include "fitting/observability.h"
#include "fitting/shading_frame.h"

namespace u3mscan::fitting {
namespace {

using Matrix7 = Eigen::Matrix<double, kFitParameterCount, kFitParameterCount>;

// A measured parameter whose posterior std at the final cluster solution exceeds this many max_std
// is left out after all (end of the cluster fit).
constexpr double kFinalStdFactor = 2.0;
// Anisotropic below this counts as at its lower bound (the y-stretch test of FitCluster), and the
// start of that test's refit (the twill preset's 0.2, well inside the bounds).
constexpr double kAnisotropyAtBound = 0.01;
constexpr double kAnisotropyProbeStart = 0.2;
// A solve with specular held that ends with roughness below the grid's smallest
// (kSmallestStartRoughness) may have hidden the held lobe in a spike between the lights; it is
// solved again from the best grid start at roughness >= kBroadStartRoughness (FitCluster).
constexpr double kBroadStartRoughness = 0.2;
// Anisotropy rotation search (FitOptions::fit_anisotropy_rotation): the cost is scanned (no solve)
// every kRotationScanStepDeg over the half turn (the stretch repeats every 180 degrees) with the
// first solve's parameters and a stretch of at least kAnisotropyProbeStart; a turn closer to 0 than
// kMinRotationDeg, or whose scanned cost is not below the solved unturned fit's, is no turn;
// otherwise the scan's vertex is solved, and refined by parabolas
// kRotationRefineStepDeg wide on the solved parameters (each followed by a solve) until the turn
// moves less than kRotationConvergedDeg, at most kRotationRefineRounds times.
constexpr int kRotationScanSteps = 12;
constexpr double kRotationScanStepDeg = 180.0 / kRotationScanSteps;
constexpr double kMinRotationDeg = 5.0;
constexpr double kRotationRefineStepDeg = 3.0;
constexpr int kRotationRefineRounds = 3;
constexpr double kRotationConvergedDeg = 0.1;
// The sheen grid (GridStart) is searched only when some observation has a Schlick weight above this.
constexpr double kSheenGridMinGrazing = 0.01;
// Start of the metallic refit of a poorly explained cluster (metallic_if_demanded).
constexpr double kMetallicStart = 0.7;

}  // namespace

ParameterMask Candidates(const FitOptions& options) {
  ParameterMask m{};
  m[kRoughness] = true;
  m[kSpecular] = true;
  m[kSpecularTint] = options.fit_specular_tint;
  m[kSheen] = options.fit_sheen;
  m[kSheenTint] = options.fit_sheen_tint;
  m[kAnisotropic] = options.fit_anisotropic;
  m[kMetallic] = options.fit_metallic;
  return m;
}

double MismatchThreshold(const FitOptions& options) {
  return std::max(options.mismatch_relative_rms, 2.0 * options.noise_relative);
}

PixelCostSettings CostSettingsFor(const FitOptions& options, const ParameterVector& params, const ParameterMask& free,
                                  double luminance_start) {
  PixelCostSettings s;
  s.loss = options.robust_loss;
  s.luminance_start = std::max(kMinStartLuminance, luminance_start);
  s.luminance_passes = LuminancePassesFor(params, free, options.luminance_passes);
  return s;
}

namespace {

// Cost over at most `pixel_limit` samples; `free` decides the luminance passes (see CostSettingsFor).
double SamplesCost(const ClusterSamples& samples, std::size_t pixel_limit, const ParameterVector& params,
                   const FitOptions& options, std::vector<double>& residuals, const ParameterMask& free = {}) {
  double cost = 0.0;
  const std::size_t pixels = std::min(pixel_limit, samples.pixels());
  for (std::size_t j = 0; j < pixels; ++j) {
    const std::size_t p = j * samples.pixels() / pixels;  // evenly spread over the samples
    const auto obs = samples.pixel(p);
    residuals.resize(3 * obs.size());
    cost += PixelResiduals(params, obs, CostSettingsFor(options, params, free, samples.luminance_start[p]), residuals.data());
  }
  return cost;
}

struct SolveOutcome {
  double initial_cost = 0.0;
  double final_cost = 0.0;
  int iterations = 0;
  bool converged = false;
  bool usable = false;
  std::string message;
};

// One Ceres solve of the shared parameters over the samples; `params` in and out.
SolveOutcome SolveClusterOnce(const ClusterSamples& samples, const ParameterMask& free, const FitOptions& options,
                              ParameterVector& params) {
  SolveOutcome outcome;
  ceres::Problem::Options problem_options;
  ceres::Problem problem(problem_options);
  ParameterVector x = params;
  for (std::size_t p = 0; p < samples.pixels(); ++p) {
    ceres::CostFunction* cost =
        MakePixelCostFunction(samples.pixel(p), CostSettingsFor(options, x, free, samples.luminance_start[p]));
    problem.AddResidualBlock(cost, nullptr, &x[0], &x[1], &x[2], &x[3], &x[4], &x[5], &x[6]);
  }
  for (int i = 0; i < kFitParameterCount; ++i) {
    problem.SetParameterLowerBound(&x[i], 0, 0.0);
    problem.SetParameterUpperBound(&x[i], 0, 1.0);
    if (!free[i]) problem.SetParameterBlockConstant(&x[i]);
  }
  ceres::Solver::Options solver_options;
  solver_options.linear_solver_type = ceres::DENSE_NORMAL_CHOLESKY;
  solver_options.num_threads = 1;  // clusters already run in parallel
  solver_options.max_num_iterations = options.max_iterations;
  solver_options.function_tolerance = options.function_tolerance;
  solver_options.parameter_tolerance = options.parameter_tolerance;
  solver_options.gradient_tolerance = options.gradient_tolerance;
  solver_options.logging_type = ceres::SILENT;
  solver_options.minimizer_progress_to_stdout = false;
  ceres::Solver::Summary summary;
  ceres::Solve(solver_options, &problem, &summary);
  outcome.initial_cost = summary.initial_cost;
  outcome.final_cost = summary.final_cost;
  outcome.iterations = static_cast<int>(summary.iterations.size());
  outcome.message = summary.message;
  bool finite = std::isfinite(summary.final_cost);
  for (double v : x) finite = finite && std::isfinite(v);
  outcome.converged = summary.termination_type == ceres::CONVERGENCE && finite;
  outcome.usable = finite && summary.termination_type != ceres::FAILURE;
  if (!finite) outcome.message = "non-finite parameters or cost: " + outcome.message;
  if (outcome.usable) params = x;
  return outcome;
}

// Mean Cauchy cost per observation (0.5 rho(|r|^2), r in sigma, 3 channels) above which a Cauchy
// solve is taken to have stalled: clean data give about 1.1 (|r|^2 ~ 3), this is |r| ~ 27 sigma on
// average. At 4 (|r| ~ 5 sigma) the woven and oblique clusters the model explains only in part
// were solved three times: the quick bench's oblique run took 28.5 s instead of 8.8.
constexpr double kCauchyStallCostPerObservation = 10.0;

// The solve with options.robust_loss. A Cauchy loss is not convex: from a start far from the data
// every observation is an outlier, its weight vanishes and the solve stalls there (a metallic
// thread fitted as a dielectric stopped at a relative residual of 0.91). A Cauchy solve that ends
// with a mean cost above kCauchyStallCostPerObservation is therefore run again from the same start
// through a Huber solve at the same scale (convex in the residuals, it gets close first), and the
// lower Cauchy cost is kept. Running the Huber solve first every time cost the balanced preset 66 %
// more time for the same maps (plain at 3x: 20 -> 34 s); the check costs nothing on data the model
// explains.
SolveOutcome SolveCluster(const ClusterSamples& samples, const ParameterMask& free, const FitOptions& options,
                          ParameterVector& params) {
  if (options.robust_loss.kind != RobustLossKind::kCauchy) return SolveClusterOnce(samples, free, options, params);
  const ParameterVector start = params;
  SolveOutcome outcome = SolveClusterOnce(samples, free, options, params);
  const double observations = std::max<double>(1.0, static_cast<double>(CountMeasurements(samples.observations)));
  if (outcome.usable && outcome.final_cost <= kCauchyStallCostPerObservation * observations) return outcome;
  FitOptions convex = options;
  convex.robust_loss.kind = RobustLossKind::kHuber;
  ParameterVector again = start;
  const SolveOutcome first = SolveClusterOnce(samples, free, convex, again);
  SolveOutcome second = SolveClusterOnce(samples, free, options, again);
  second.iterations += first.iterations + outcome.iterations;
  if (!second.usable && first.usable) {
    second.usable = true;  // `again` holds the Huber solve
    second.message = "Cauchy solve failed (" + second.message + "); kept the Huber solve";
  }
  if (second.usable && (!outcome.usable || second.final_cost < outcome.final_cost)) {
    params = again;
    return second;
  }
  outcome.iterations = second.iterations;
  return outcome;
}

// Turns every sample's tangent by `turn_deg` further about its normal (rotation_deg grows by it).
void TurnSamples(ClusterSamples& samples, double turn_deg) {
  for (LocalObservation& o : samples.observations) {
    o.light_local = TurnTangent(o.light_local, turn_deg);
    o.view_local = TurnTangent(o.view_local, turn_deg);
  }
  samples.rotation_deg = WrapHalfTurnDeg(samples.rotation_deg + turn_deg);
}

// The anisotropy rotation search of FitOptions::fit_anisotropy_rotation (steps at kRotationScanSteps
// above), from the solution `params` (with `outcome`) of the samples as they are. A turn is adopted
// when its anisotropic is off the bound and it lowers chi^2 (effective units) by more than
// default_rejection_chi2: the samples are turned, `params` and `outcome` are its solve's.
// Returns the chi^2 gain of the adopted turn, 0 when none was.
double SearchAnisotropyRotation(ClusterSamples& samples, const ParameterMask& free, const FitOptions& options,
                                ParameterVector& params, SolveOutcome& outcome, std::vector<double>& residuals) {
  // Vertex (degrees) of the parabola through costs at turn - step, turn, turn + step.
  auto vertex = [](double turn, double step, double below, double at, double above) {
    const double curvature = below - 2.0 * at + above;
    if (!(curvature > 0.0) || !std::isfinite(curvature)) return turn;
    return WrapHalfTurnDeg(turn + std::clamp(0.5 * step * (below - above) / curvature, -step, step));
  };
  // Cost of `p` with the samples turned by `turn` (a copy; the samples stay as they are).
  ClusterSamples turned;
  auto cost_turned = [&](double turn, const ParameterVector& p) {
    turned = samples;
    TurnSamples(turned, turn);
    return SamplesCost(turned, turned.pixels(), p, options, residuals, free);
  };
  // 1. Scan without solving.
  ParameterVector probe = params;
  probe[kAnisotropic] = std::max(params[kAnisotropic], kAnisotropyProbeStart);
  double scan[kRotationScanSteps];
  int best = 0;
  for (int k = 0; k < kRotationScanSteps; ++k) {
    scan[k] = cost_turned(k * kRotationScanStepDeg, probe);
    if (scan[k] < scan[best]) best = k;
  }
  double turn = vertex(best * kRotationScanStepDeg, kRotationScanStepDeg,
                       scan[(best + kRotationScanSteps - 1) % kRotationScanSteps], scan[best],
                       scan[(best + 1) % kRotationScanSteps]);
  if (std::min(turn, 180.0 - turn) < kMinRotationDeg) return 0.0;
  // Worth the solves only when the turned stretch, not yet solved, already explains the data better
  // than the solved unturned fit (an isotropic lobe, or a weave's misfit, costs about the same
  // stretched any way and is not).
  const double cost_unturned = SamplesCost(samples, samples.pixels(), params, options, residuals, free);
  if (!(scan[best] < cost_unturned)) return 0.0;
  // 2. Solve there, then refine the turn by parabolas on the solved parameters, solving again at
  // each new turn, until it stops moving.
  ParameterVector solved = probe;
  turned = samples;
  TurnSamples(turned, turn);
  SolveOutcome solve = SolveCluster(turned, free, options, solved);
  if (!solve.usable) return 0.0;
  for (int round = 0; round < kRotationRefineRounds; ++round) {
    const double at = SamplesCost(turned, turned.pixels(), solved, options, residuals, free);
    const double refined = vertex(turn, kRotationRefineStepDeg, cost_turned(turn - kRotationRefineStepDeg, solved), at,
                                  cost_turned(turn + kRotationRefineStepDeg, solved));
    const double moved = std::abs(refined - turn);
    if (std::min(moved, 180.0 - moved) < kRotationConvergedDeg) break;
    ParameterVector again = solved;
    turned = samples;
    TurnSamples(turned, refined);
    const SolveOutcome next = SolveCluster(turned, free, options, again);
    if (!next.usable) break;
    solved = again;
    solve = next;
    turn = refined;
  }
  turned = samples;
  TurnSamples(turned, turn);
  // 3. Adopted only when it explains the data clearly better than the unturned solution.
  if (!(solved[kAnisotropic] > kAnisotropyAtBound)) {
    LogDebug() << "fitting: anisotropy turn " << turn << " deg not adopted: the solved stretch is at its bound";
    return 0.0;
  }
  const double cost = SamplesCost(turned, turned.pixels(), solved, options, residuals, free);
  ObservabilityContext context;
  context.pixel_count = static_cast<int>(samples.pixels());
  context.residual_count = 3 * CountMeasurements(samples.observations);
  context.cost = cost;
  const double gain = EffectiveChi2Increase(cost, cost_unturned, context, options.observability);
  if (!(gain > options.observability.default_rejection_chi2)) {
    LogDebug() << "fitting: anisotropy turn " << turn << " deg not adopted: chi^2 -" << gain << " only";
    return 0.0;
  }
  samples = std::move(turned);
  params = solved;
  outcome = solve;
  return gain;
}

// Fisher information J^T J (weighted-residual units) of the samples at `params`, each pixel's
// normal tilts marginalised when the options say so (observability.h), and the cost. Through a
// Cauchy loss the information is taken as Huber's at the same scale: Cauchy's weight is already
// 0.8 at 1 sigma, so clean data would look less informative than they are (the bump field's
// specular std 0.057 instead of under 0.05: left out); Huber keeps weight 1 within its scale and
// still discounts the outliers beyond it. The cost stays the fit's own (the chi^2 tests compare it
// with SamplesCost).
Matrix7 FisherInformation(const ClusterSamples& samples, const ParameterVector& params, const FitOptions& options,
                          const ParameterMask& free, double* cost, int* residual_count) {
  const bool cauchy = options.robust_loss.kind == RobustLossKind::kCauchy;
  std::vector<double> fit_residuals;
  Matrix7 fisher = Matrix7::Zero();
  *cost = 0.0;
  *residual_count = 0;
  Eigen::VectorXd r;
  Eigen::MatrixXd j;
  Eigen::MatrixXd j_normal;
  std::vector<LocalObservation> tilted;
  for (std::size_t p = 0; p < samples.pixels(); ++p) {
    const PixelCostSettings fit_settings = CostSettingsFor(options, params, free, samples.luminance_start[p]);
    PixelCostSettings settings = fit_settings;
    if (cauchy) settings.loss.kind = RobustLossKind::kHuber;
    if (!EvaluatePixelJacobian(params, samples.pixel(p), settings, &r, &j)) continue;
    if (!r.allFinite() || !j.allFinite()) continue;
    j_normal.resize(0, 0);
    if (options.observability.marginalise_normals &&
        !EvaluateNormalTiltJacobian(params, samples.pixel(p), settings, tilted, &j_normal)) {
      continue;
    }
    fisher.noalias() += PixelInformation(j, j_normal);
    if (cauchy) {
      fit_residuals.resize(static_cast<std::size_t>(r.size()));
      *cost += PixelResiduals(params, samples.pixel(p), fit_settings, fit_residuals.data());
    } else {
      *cost += 0.5 * r.squaredNorm();
    }
    *residual_count += 3 * CountMeasurements(samples.pixel(p));  // a facet run's continued slots are always 0
  }
  return fisher;
}

}  // namespace

ClusterFit FitCluster(int id, ClusterSamples& samples, const FitOptions& options, const ParameterMask& candidates,
                      const ParameterVector& held, bool search_rotation, double* observability_s) {
  ClusterFit fit;
  fit.id = id;
  fit.sample_count = static_cast<int>(samples.pixels());
  ParameterVector params = held;
  if (samples.pixels() == 0) {
    fit.message = "no usable pixels";
    for (int i = 0; i < kFitParameterCount; ++i) {
      fit.parameters[i] = {params[i], std::numeric_limits<double>::infinity(), false, "no usable pixels in the cluster", true, ""};
    }
    return fit;
  }

  // Coarse grid start (tints, anisotropy, metallic at 0: the model is linear in C there).
  double max_grazing = 0.0;
  for (const LocalObservation& o : samples.observations) max_grazing = std::max(max_grazing, GrazingWeight(o));
  const bool sheen_grid = max_grazing > kSheenGridMinGrazing;  // GridStart skips a sheen it does not fit
  std::vector<double> residuals;
  const std::size_t grid_pixels = static_cast<std::size_t>(options.grid_samples_per_cluster);
  // The start grid's cost: over grid_samples_per_cluster samples, evenly spread (SamplesCost).
  auto grid_cost = [&](const ParameterVector& trial) {
    return SamplesCost(samples, grid_pixels, trial, options, residuals);
  };
  const ParameterVector start = GridStart(candidates, held, sheen_grid, grid_cost);
  params = start;

  // Start luminance of each sample's base colour, from the grid start.
  ParameterMask none{};
  for (std::size_t p = 0; p < samples.pixels(); ++p) {
    const Eigen::Vector3d c = SolveBaseColor(params, samples.pixel(p), CostSettingsFor(options, params, none, 0.2));
    samples.luminance_start[p] = std::max(kMinStartLuminance, Luminance(c));
  }

  ObservabilityContext context;
  context.pixel_count = static_cast<int>(samples.pixels());
  context.max_grazing_weight = max_grazing;
  Matrix7 fisher;
  // Fisher information (and the context's cost) at `p` with `free` deciding the colour passes.
  auto update_fisher = [&](const ParameterVector& p, const ParameterMask& free) {
    const double t_obs = SteadySeconds();
    double cost = 0.0;
    int residual_count = 0;
    fisher = FisherInformation(samples, p, options, free, &cost, &residual_count);
    context.cost = cost;
    context.residual_count = residual_count;
    *observability_s += SteadySeconds() - t_obs;
  };
  // The leave-out rule over `free`, then: keep a left-out parameter whose default the data exclude.
  auto decide = [&](const ParameterVector& p, const ParameterMask& free) {
    update_fisher(p, free);
    const double t_obs = SteadySeconds();
    ObservabilityDecision d = DecideObservability(fisher, free, context, options.observability);
    const double cost_at_fit = SamplesCost(samples, samples.pixels(), p, options, residuals, free);
    for (int i = 0; i < kFitParameterCount; ++i) {
      if (!free[i] || d.measured[i]) continue;
      ParameterVector trial_default = p;
      trial_default[i] = FitParameterDefault(static_cast<FitParameter>(i));
      const double cost_at_default = SamplesCost(samples, samples.pixels(), trial_default, options, residuals, free);
      const double chi2 = EffectiveChi2Increase(cost_at_fit, cost_at_default, context, options.observability);
      if (chi2 > options.observability.default_rejection_chi2) {
        d.measured[i] = true;
        char buffer[200];
        std::snprintf(buffer, sizeof buffer,
                      "weakly constrained (posterior std %.3g), but the data exclude the default %.3g "
                      "(chi^2 +%.3g): kept at the fitted value",
                      d.std_dev[i], FitParameterDefault(static_cast<FitParameter>(i)), chi2);
        d.reason[i] = buffer;
      }
    }
    *observability_s += SteadySeconds() - t_obs;
    return d;
  };
  // Left-out parameters to their defaults (held ones stay held) and a refit without them; returns
  // the solve's outcome.
  auto refit_without_left_out = [&](ParameterVector& p, const ParameterMask& measured) {
    for (int i = 0; i < kFitParameterCount; ++i) {
      if (!measured[i]) p[i] = candidates[i] ? FitParameterDefault(static_cast<FitParameter>(i)) : held[i];
    }
    const ParameterVector before = p;
    SolveOutcome o = SolveCluster(samples, measured, options, p);
    if (!o.usable) {
      LogError() << "fitting: cluster " << id << " refit failed (" << o.message << ")";
      p = before;
      o.converged = false;
      o.message = "refit failed: " + o.message;
      return o;
    }
    return o;
  };

  // Relative RMS residual (unweighted) and mean base colour over the samples.
  auto summarise = [&](const ParameterVector& p, const ParameterMask& free, Eigen::Vector3d* mean_color) {
    Eigen::Vector3d color_sum = Eigen::Vector3d::Zero();
    double err2 = 0.0, data2 = 0.0;
    for (std::size_t i = 0; i < samples.pixels(); ++i) {
      const auto obs = samples.pixel(i);
      const Eigen::Vector3d c = SolveBaseColor(p, obs, CostSettingsFor(options, p, free, samples.luminance_start[i]));
      color_sum += c;
      for (std::size_t begin = 0, end = 0; begin < obs.size(); begin = end) {  // per measurement (facet runs)
        const Eigen::Vector3d predicted = RenderRun(p, c, obs, begin, &end);
        err2 += (predicted - obs[end - 1].rgb).squaredNorm();
        data2 += obs[end - 1].rgb.squaredNorm();
      }
    }
    if (mean_color != nullptr) *mean_color = color_sum / static_cast<double>(samples.pixels());
    return data2 > 0.0 ? std::sqrt(err2 / data2) : 0.0;
  };

  // First solve with every candidate free.
  SolveOutcome outcome = SolveCluster(samples, candidates, options, params);
  if (!outcome.usable) {
    LogError() << "fitting: cluster " << id << " solve failed (" << outcome.message << "); keeping its grid start";
    params = start;
  }
  // A solve with specular held from the start (at the maps' default or uniform value: a refit after
  // a rule over the clusters) can end with roughness near its lower bound: a spike between the
  // lights that hides a held lobe the data do not show, since the robust loss lets the few
  // observations the spike hits go (denim, near rig, best preset: relative RMS 4.30 and 1.32, both
  // clusters then unusable). Below kSmallestStartRoughness the cluster is solved again from the best grid
  // start at roughness >= kBroadStartRoughness, and that solution is taken when it ends at or above
  // kSmallestStartRoughness and explains the data better (the relative RMS residual that Usable judges).
  // Not after this fit's own refit without a left-out specular: there it moved a woven cluster's
  // passes to a lobe-less fit at the roughness bound (twill, distant, balanced: roughness error
  // 0.108 -> 0.171; docs/fitting.md).
  if (!candidates[kSpecular] && candidates[kRoughness] && outcome.usable && params[kRoughness] < kSmallestStartRoughness) {
    ParameterVector broad = GridStart(candidates, held, sheen_grid, grid_cost, kBroadStartRoughness);
    const SolveOutcome broad_outcome = SolveCluster(samples, candidates, options, broad);
    const int iterations = outcome.iterations + broad_outcome.iterations;
    if (broad_outcome.usable && broad[kRoughness] >= kSmallestStartRoughness &&
        summarise(broad, candidates, nullptr) < summarise(params, candidates, nullptr)) {
      LogInfo() << "fitting: cluster " << id << ": roughness " << params[kRoughness] << " hid the held specular "
                << params[kSpecular] << "; " << broad[kRoughness] << " from a broad start explains the data better";
      params = broad;
      outcome = broad_outcome;
    }
    outcome.iterations = iterations;
  }
  if (search_rotation && options.fit_anisotropy_rotation && candidates[kAnisotropic] && outcome.usable) {
    const double gain = SearchAnisotropyRotation(samples, candidates, options, params, outcome, residuals);
    if (gain > 0.0) {
      LogInfo() << "fitting: cluster " << id << ": anisotropy rotation " << samples.rotation_deg << " deg (chi^2 -"
                << gain << ")";
    }
  }
  fit.anisotropy_rotation_deg = samples.rotation_deg;
  // Restart the colour's luminance iteration from this solution: later solves and the
  // observability step then need only `luminance_passes` (2) passes to be converged.
  for (std::size_t p = 0; p < samples.pixels(); ++p) {
    const Eigen::Vector3d c =
        SolveBaseColor(params, samples.pixel(p), CostSettingsFor(options, params, candidates, samples.luminance_start[p]));
    if (c.allFinite()) samples.luminance_start[p] = std::max(kMinStartLuminance, Luminance(c));
  }
  const SolveOutcome first = outcome;
  int iterations = first.iterations;

  // Observability at the solution, then a refit with the left-out parameters at their defaults.
  ObservabilityDecision decision = decide(params, candidates);
  if (decision.measured != candidates) {
    outcome = refit_without_left_out(params, decision.measured);
    iterations += outcome.iterations;
    update_fisher(params, decision.measured);
  }

  fit.rms_relative_residual = summarise(params, decision.measured, &fit.mean_base_color);

  // Metallic only when the data demand it: a poorly explained cluster is refitted with metallic
  // free; that fit replaces the dielectric one if it explains the data (relative RMS residual
  // within mismatch_relative_rms), chi^2 drops by more than default_rejection_chi2 and metallic is
  // then measured. Observability is decided again for the new model.
  const int metal = kMetallic;
  const double mismatch_rms = MismatchThreshold(options);
  if (!candidates[metal] && options.metallic_if_demanded && fit.rms_relative_residual > mismatch_rms) {
    ParameterMask free = decision.measured;
    free[metal] = true;
    ParameterVector trial = params;
    trial[metal] = kMetallicStart;
    SolveOutcome metal_outcome = SolveCluster(samples, free, options, trial);
    if (metal_outcome.usable) {
      const double cost_now = SamplesCost(samples, samples.pixels(), params, options, residuals, decision.measured);
      const double cost_metal = SamplesCost(samples, samples.pixels(), trial, options, residuals, free);
      const ObservabilityContext dielectric_context = context;
      const Matrix7 dielectric_fisher = fisher;
      ObservabilityDecision metal_decision = decide(trial, free);
      const double gain = EffectiveChi2Increase(cost_metal, cost_now, context, options.observability);
      // Demanded = the metallic model explains the data (not merely a better misfit).
      const bool explains = summarise(trial, free, nullptr) <= mismatch_rms;
      if (explains && gain > options.observability.default_rejection_chi2 && metal_decision.measured[metal]) {
        params = trial;
        iterations += metal_outcome.iterations;
        if (metal_decision.measured != free) {
          metal_outcome = refit_without_left_out(params, metal_decision.measured);
          iterations += metal_outcome.iterations;
          update_fisher(params, metal_decision.measured);
        }
        char buffer[160];
        std::snprintf(buffer, sizeof buffer, "demanded by the data: chi^2 -%.3g with metallic free", gain);
        metal_decision.reason[metal] = buffer;
        decision = metal_decision;
        outcome = metal_outcome;
        fit.rms_relative_residual = summarise(params, decision.measured, &fit.mean_base_color);
      } else {
        context = dielectric_context;  // keep the dielectric fit's figures
        fisher = dielectric_fisher;
      }
    }
  }

  const ParameterVector std_dev = PosteriorStdDev(fisher, decision.measured, context, options.observability);
  fit.initial_cost = first.initial_cost;
  fit.final_cost = outcome.final_cost;
  fit.iterations = iterations;
  fit.converged = outcome.converged;  // the final solve is what counts
  fit.message = outcome.message;
  for (int i = 0; i < kFitParameterCount; ++i) {
    ParameterEstimate& e = fit.parameters[i];
    e.value = params[i];
    e.measured = decision.measured[i];
    e.std_dev = e.measured ? std_dev[i] : std::numeric_limits<double>::infinity();
    e.reason = decision.reason[i];  // for a measured parameter only a "weakly constrained" / "demanded" note
    // The observability decision was taken before the last refit; a parameter that the final
    // solution clearly no longer constrains (posterior std above twice max_std, e.g. specular on a
    // near-black sample) is left out rather than reported as measured. Twice: the last refit
    // moves the std a little, which alone is no reason to drop a parameter.
    if (e.measured && !(std_dev[i] <= kFinalStdFactor * options.observability.max_std)) {
      char buffer[160];
      std::snprintf(buffer, sizeof buffer, "not constrained by this capture (posterior std %.3g > %.3g at the final solution)",
                    std_dev[i], kFinalStdFactor * options.observability.max_std);
      e.measured = false;
      e.reason = buffer;
    }
  }

  // Anisotropy is modelled along the shading frame's x axis (world +x projected: U3M
  // anisotropy_rotation 0) only, with anisotropic in [0, 1]. A highlight stretched along y (a
  // twill's warp when its weft runs along x) is outside that model and fits as 0 at the bound, with
  // a small std that means nothing there. Test it: refit anisotropy (and roughness) with the frame
  // turned by 90 degrees; if that explains the data clearly better, 0 is not the fabric's value.
  ParameterEstimate& aniso = fit.parameters[kAnisotropic];
  // A turn means nothing without a measured stretch: the parameters are then those of any turn.
  if (!aniso.measured) fit.anisotropy_rotation_deg = 0.0;
  if (!options.fit_anisotropy_rotation && candidates[kAnisotropic] && aniso.value < kAnisotropyAtBound) {
    ClusterSamples turned = samples;
    TurnSamples(turned, 90.0);
    ParameterMask mask = decision.measured;
    mask[kAnisotropic] = true;
    ParameterMask free{};
    free[kAnisotropic] = true;
    free[kRoughness] = decision.measured[kRoughness];
    ParameterVector across = params;
    across[kAnisotropic] = kAnisotropyProbeStart;
    const SolveOutcome probe = SolveCluster(turned, free, options, across);
    if (probe.usable && across[kAnisotropic] > kAnisotropyAtBound) {
      const double cost_now = SamplesCost(samples, samples.pixels(), params, options, residuals, mask);
      const double cost_across = SamplesCost(turned, turned.pixels(), across, options, residuals, mask);
      const double gain = EffectiveChi2Increase(cost_across, cost_now, context, options.observability);
      if (gain > options.observability.default_rejection_chi2) {
        char buffer[320];
        std::snprintf(buffer, sizeof buffer,
                      "the highlights are stretched along the image y axis (anisotropic %.2f with the tangent turned "
                      "90 deg, chi^2 -%.3g), which the fit's x-axis tangent (anisotropy_rotation 0) cannot represent",
                      across[kAnisotropic], gain);
        if (aniso.measured) {
          aniso.reliable = false;
          aniso.unreliable_reason = std::string(buffer) + ": the fitted 0 is not the fabric's value";
        } else {
          aniso.reason += std::string(aniso.reason.empty() ? "" : "; ") + buffer;
        }
      }
    }
  }
  return fit;
}

double HighlightShare(const ClusterSamples& samples, const ParameterVector& params, const ParameterMask& free,
                      const FitOptions& options) {
  if (samples.pixels() == 0) return 0.0;
  ParameterVector matte = params;
  matte[kSpecular] = 0.0;
  std::size_t with_highlight = 0;
  for (std::size_t p = 0; p < samples.pixels(); ++p) {
    const auto obs = samples.pixel(p);
    const Eigen::Vector3d color = SolveBaseColor(params, obs, CostSettingsFor(options, params, free, samples.luminance_start[p]));
    if (!color.allFinite()) continue;
    for (std::size_t begin = 0, end = 0; begin < obs.size(); begin = end) {  // per measurement (facet runs)
      const double full = Luminance(RenderRun(params, color, obs, begin, &end));
      const double lobe = full - Luminance(RenderRun(matte, color, obs, begin, &end));
      if (full > 0.0 && lobe >= options.highlight_lobe_fraction * full) {
        ++with_highlight;
        break;
      }
    }
  }
  return static_cast<double>(with_highlight) / static_cast<double>(samples.pixels());
}

}  // namespace u3mscan::fitting
