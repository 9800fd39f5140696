#pragma once
// Fitting the Principled parameters of a fabric from a calibrated Stack (core/stack.h) and the
// reconstruction's per-pixel normals, albedo and height. Algorithm and figures: docs/fitting.md.
//
// Stages (each timed):
//   1. gather:        for an evenly strided candidate set of pixels, the usable observations in
//                     the local shading frame (z = normal, x = world +x projected into the
//                     tangent plane) and the appearance features;
//   2. clustering:    k-means on albedo and gloss profile (fitting/clustering.h);
//   3. cluster fit:   per cluster, the shared parameters (roughness, specular, tints, sheen,
//                     anisotropic; metallic only when the data demand it) on a deterministic
//                     sample of its pixels, base colour per pixel in closed form; coarse grid
//                     start, then Ceres (Levenberg-Marquardt, bounds [0, 1]); clusters in parallel;
//   4. observability: parameters the capture does not constrain are left out (U3M default, no
//                     texture) and the cluster refitted without them (fitting/observability.h);
//   5. per pixel:     every pixel's normal is refined with the full model at its cluster's
//                     parameters (FitResult::normals), then it gets its closed-form base colour;
//                     where its own highlights carry
//                     enough information, roughness (optionally specular) is refined by a damped
//                     Gauss-Newton step regularised toward the cluster value. No Ceres problem per
//                     pixel, no allocation per pixel.

#include <Eigen/Core>
#include <array>
#include <functional>
#include <string>
#include <vector>

#include "core/image.h"
#include "core/progress.h"
#include "core/stack.h"
#include "fitting/brdf_cost.h"
#include "fitting/clustering.h"
#include "fitting/observability.h"

namespace u3mscan::fitting {

// Cluster values only, or cluster values refined per pixel where a pixel's own highlights allow.
enum class FitMode { kClusters, kPerPixel };
// "clusters" / "per-pixel"; ParseFitMode throws std::invalid_argument for another word.
const char* FitModeName(FitMode mode);
FitMode ParseFitMode(const std::string& name);

struct FitOptions {
  ClusteringOptions clustering;
  ObservabilityOptions observability;

  // Pixels per cluster the shared parameters are fitted on (evenly spread over the cluster).
  int samples_per_cluster = 192;
  // Pixels per cluster the coarse start grid is evaluated on (a subset of the samples).
  int grid_samples_per_cluster = 48;
  // Noise model of one channel of one observation, sigma = noise_floor * level + noise_relative * |rgb|,
  // level = median luminance of that observation image (so the floor follows the light's brightness).
  double noise_relative = 0.01;
  double noise_floor = 0.005;
  // Cauchy at 2 sigma, not Huber: what the model cannot explain at one pixel (a yarn's cast shadow
  // over part of the pixel, the highlight of a neighbouring fibre) is darker or brighter by tens of
  // sigma, and Huber's linear pull let those observations bend the lobe. Measured at 3x with the
  // balanced preset (docs/fitting.md, "Robust loss"): plain roughness error 0.039 -> 0.026 and
  // specular 0.134 -> 0.102, twill roughness 0.077 -> 0.043, knit 0.110 -> 0.063. A cluster
  // solve that stalls is run again from a Huber solve, and the observability's information goes
  // through Huber (cluster_fit.cc, SolveCluster and FisherInformation).
  RobustLoss robust_loss{RobustLossKind::kCauchy, 2.0};
  // Observations with cos_l or cos_v below this are not used (grazing to the point of shadowing).
  double min_cos = 0.02;
  // Pixels with fewer usable observations are not fitted (their maps hold the cluster / defaults).
  int min_observations = 4;
  // Which parameters the fit may estimate; the others stay at their U3M defaults. Metallic is off:
  // fabric is a dielectric, and "metallic" would trade off against specular and base colour.
  bool fit_specular_tint = true;
  bool fit_sheen = true;
  bool fit_sheen_tint = true;
  bool fit_anisotropic = true;
  // The direction of the anisotropic stretch per cluster (U3M anisotropy_rotation, shading_frame.h):
  // with anisotropic a candidate, the first solve is repeated with the tangent turned by 45, 90 and
  // 135 degrees, a parabola through the best and its neighbours gives one more angle, and the best
  // turn is kept when it lowers chi^2 (effective units, observability.h) by more than
  // observability.default_rejection_chi2; otherwise the cluster stays at 0. Off: the tangent is
  // world +x projected, and a stretch along y is only flagged (docs/fitting.md, "Anisotropy").
  bool fit_anisotropy_rotation = true;
  bool fit_metallic = false;
  // With fit_metallic off, a cluster the model explains poorly (mismatch_relative_rms) is refitted
  // with metallic free, and metallic is kept only if the metallic model then explains the data
  // (see docs/fitting.md).
  bool metallic_if_demanded = true;
  // Ceres.
  int max_iterations = 100;
  double function_tolerance = 1e-8;
  double parameter_tolerance = 1e-10;
  double gradient_tolerance = 1e-12;
  // Passes of the secant iteration for the luminance of the base colour when a tint is in play
  // (each pass is one BRDF evaluation per observation; the start is refreshed after each solve).
  int luminance_passes = 2;
  // A cluster whose relative RMS residual exceeds max(this, 2 * noise_relative) is reported as a
  // likely model mismatch in the convergence messages (the Principled model does not explain its
  // data).
  double mismatch_relative_rms = 0.05;
  // A cluster whose relative RMS residual exceeds this measures nothing: every shared parameter is
  // left out with the reason (the model does not explain the data; values would be biased).
  double unusable_relative_rms = 0.15;
  // Reliability (docs/fitting.md, "Reliable or not"): a measured parameter is flagged unreliable
  // (written, with the flag and the reason in the reports) when the fit's own evidence says its
  // value may be off by more than its posterior std:
  //   - its cluster's relative RMS residual exceeds the mismatch threshold above (the model does
  //     not explain the data: the value is biased by an unknown amount);
  //   - for specular and roughness: fewer than `min_highlight_share` of the cluster's samples show a
  //     usable observation in which the fitted specular lobe carries at least
  //     `highlight_lobe_fraction` of the signal (highlights fell between the lights or saturated: the
  //     value is inferred from their absence).
  // A map is flagged when the clusters that flag it hold more than `unreliable_pixel_share` of the
  // pixels that measure it, or when the clusters that measure it hold less than
  // 1 - `unreliable_pixel_share` of the fitted pixels (the others hold the U3M default).
  // Lobe fraction: 2.5 x the default relative noise; a lobe below it hides in the noise and the
  // diffuse shape. Measured per-pixel largest lobe fraction (stability suite, preset fast): plain
  // bump field (roughness 0.6) 0.10-0.14, white sample with clipping 0.04-0.06, woven mirror and
  // open-gauze presets (values wrong by 0.3-0.5) 0.000-0.02.
  double min_highlight_share = 0.05;
  double highlight_lobe_fraction = 0.025;
  double unreliable_pixel_share = 0.5;
  // Per-pixel refinement of roughness (and optionally specular, which a single pixel rarely pins
  // down; docs/principled-brdf.md). Costs ~3 extra residual evaluations per refined pixel and
  // Gauss-Newton iteration, 2 more with specular. FitMode::kClusters turns it off (cluster values
  // only, per pixel just the closed-form base colour).
  FitMode mode = FitMode::kPerPixel;
  bool refine_specular_per_pixel = false;
  double pixel_prior_std = 0.1;      // regularisation toward the cluster value (parameter units)
  double pixel_max_std = 0.05;       // a pixel's value is kept only if its posterior std is below this
  // The regularisation from the cluster's own spread (empirical Bayes): each cluster's prior std
  // per refined parameter is the spread its pixels show beyond their noise, estimated on its samples
  // (ClusterFit::pixel_prior_std), at most pixel_prior_std. A cluster whose pixels share one value
  // then holds it instead of writing their noise into the map; one whose threads differ follows
  // them (docs/fitting.md, "Per-pixel spread from the samples"). Off: pixel_prior_std everywhere.
  bool pixel_prior_from_samples = true;
  // Screen: a pixel is refined only if its largest reflectance ratio exceeds its median one by
  // 1 / (1 - this), i.e. it shows a highlight of at least this share.
  double pixel_min_specular_fraction = 0.1;
  int pixel_iterations = 1;
  // Normal refinement of the cluster samples (docs/fitting.md): photometric stereo's Lambertian
  // normals lean toward the highlights; each pass refits every sampled pixel's normal with the full
  // model at the cluster's parameters (damped Gauss-Newton, at most normal_iterations steps, never
  // more than normal_max_change_deg from the reconstruction's normal), then refits the cluster.
  // Passes run to convergence: they stop when the mean angle between a pass's normals and the
  // previous pass's (the reconstruction's for the first) is below normal_refinement_tolerance_deg,
  // or after normal_refinement_max_passes. A fixed 2 passes stopped short on the smooth bump field
  // (specular 0.37-0.43 for 0.5; converged 0.49-0.50). 0 passes: the reconstruction's normals.
  // 0.05 deg costs 40 % less than 0.01 deg (each pass refits the cluster) for a specular about
  // 0.01-0.03 lower on the bump field (docs/fitting.md); the best preset uses 0.01.
  int normal_refinement_max_passes = 8;
  double normal_refinement_tolerance_deg = 0.05;
  int normal_iterations = 5;
  double normal_max_change_deg = 10.0;
  // Every pixel's normal refined the same way after the fit, at its own fitted parameters
  // (FitResult::normals; the pipeline writes those and integrates the height from them), with at
  // most pixel_normal_iterations damped Gauss-Newton steps. Off: FitResult::normals stays empty.
  bool refine_pixel_normals = true;
  int pixel_normal_iterations = 3;
  // Where the per-pixel step refines the lobe (kPerPixel, a pixel that shows a highlight) and
  // refine_pixel_normals is on: the pixel's normal and lobe (roughness, and specular with
  // refine_specular_per_pixel) in one damped Gauss-Newton of at most pixel_joint_iterations steps,
  // started from the normal refined at the cluster's lobe. A thread whose lobe differs from its
  // cluster's (denim's warp, roughness 0.74-0.96) otherwise keeps a normal bent to explain the
  // cluster's lobe, and its lobe then fits that bent normal (docs/fitting.md, "Normal and lobe
  // together"). The joint values are kept where every lobe parameter's posterior std (the normal's
  // tilts marginalised) is below pixel_max_std, else the two steps one after the other as before.
  bool refine_normal_with_lobe = true;
  int pixel_joint_iterations = 6;
  // Threads: clusters and pixels run through core/parallel.h (SetThreadCount).

  bool Check() const;
};

// One shared parameter of one cluster.
struct ParameterEstimate {
  double value = 0.0;
  double std_dev = 0.0;  // posterior standard deviation; inf when not measured
  bool measured = false;
  std::string reason;    // why it was left out; for a measured one only a "weakly constrained" note
  // Measured, but the fit's evidence says the value may be off by more than std_dev (see
  // FitOptions, "Reliability"); `unreliable_reason` says which evidence. Meaningless if !measured.
  bool reliable = true;
  std::string unreliable_reason;
};

struct ClusterFit {
  int id = 0;
  std::int64_t pixel_count = 0;
  int sample_count = 0;
  std::array<ParameterEstimate, kFitParameterCount> parameters;
  // Turn of the tangent about the normal (degrees, [0, 180), shading_frame.h) the parameters
  // belong to; 0 unless FitOptions::fit_anisotropy_rotation found a turned stretch.
  double anisotropy_rotation_deg = 0.0;
  Eigen::Vector3d mean_base_color = Eigen::Vector3d::Zero();  // linear RGB over the samples
  double initial_cost = 0.0;         // Ceres cost at the grid start
  double final_cost = 0.0;           // Ceres cost at the solution
  double rms_relative_residual = 0;  // RMS of (prediction - data) / data over sampled observations
  // Evidence for the reliability verdict, over the cluster's samples: share of their observations
  // dropped as saturated, and share of samples with a usable observation dominated by the fitted
  // specular lobe (FitOptions::highlight_lobe_fraction).
  double saturated_share = 0.0;
  double highlight_share = 0.0;
  int iterations = 0;
  // Normal refinement of the samples: passes run, and the mean normal change (deg) of the last one
  // (below FitOptions::normal_refinement_tolerance_deg when it converged).
  int normal_passes = 0;
  double normal_change_deg = 0.0;
  // Prior std (parameter units) of the per-pixel step toward the cluster's value, per parameter it
  // refines (roughness; specular with FitOptions::refine_specular_per_pixel; 0 for the others):
  // sqrt(max(0, mean over samples of (x - value)^2 - s^2)), x a sample's own estimate and s its
  // std, capped at FitOptions::pixel_prior_std (FitOptions::pixel_prior_from_samples).
  ParameterVector pixel_prior_std{};
  bool converged = false;
  std::string message;               // Ceres termination / failure text
};

// One output map as the U3M writer should treat it.
struct MapReport {
  bool measured = false;   // false: write the U3M default, no texture
  bool constant = false;   // measured but uniform within noise: write `value`, no texture
  double value = 0.0;      // default (not measured), constant, or pixel mean (texture)
  double spread = 0.0;     // standard deviation over fitted pixels
  std::string reason;      // why not measured / why constant
  // Measured, but flagged unreliable by the clusters that hold most of its pixels (see FitOptions,
  // "Reliability"): write it with the flag, never as a trusted value.
  bool reliable = true;
  std::string unreliable_reason;
};

struct StageTimes {
  double gather_s = 0.0;
  double clustering_s = 0.0;
  double cluster_fit_s = 0.0;
  double observability_s = 0.0;  // included in cluster_fit_s (refits), reported separately
  double per_pixel_s = 0.0;
  double total_s = 0.0;
};

struct ConvergenceReport {
  bool all_converged = true;
  int clusters_failed = 0;              // not converged or numerically failed
  std::vector<std::string> messages;    // one line per problem or mismatch warning, empty when all is well
  std::int64_t pixels_fitted = 0;       // pixels with enough observations
  std::int64_t pixels_refined = 0;      // pixels whose own roughness / specular were kept
};

// The U3M visualization key a parameter map belongs to ("roughness", "specular_value",
// "specular_tint", "sheen_value", "sheen_tint", "anisotropy_value", "metalness").
const char* U3mParameterName(FitParameter parameter);

struct FitResult {
  // Per-pixel maps on the stack's grid (pitch_mm set). base_color is 3 channels, linear RGB,
  // clamped to [0, 1]. A scalar map whose parameter was not measured is EMPTY (maps[i].measured is
  // false, write the U3M default); a constant map is filled with its value.
  Image base_color;
  std::array<Image, kFitParameterCount> parameter_maps;  // index = FitParameter
  Image cluster_id;  // 1 channel, cluster index, -1 for pixels without enough observations
  // 3 channels, unit, world frame: every fitted pixel's normal refined with the full model at its
  // cluster's parameters (FitOptions::refine_pixel_normals), the reconstruction's elsewhere; empty
  // when the option is off. Photometric stereo's Lambertian normals lean toward the highlights of a
  // glossy fabric; these are the normals the fitted maps belong with (write them, integrate the
  // height from them, render with them).
  Image normals;
  std::array<MapReport, kFitParameterCount> maps;
  // Anisotropy rotation (degrees, [0, 180), shading_frame.h) of every pixel: its cluster's. Empty
  // when every cluster's is 0 or anisotropic is not measured; `rotation_report` says how to write
  // U3M anisotropy_rotation (measured: constant or texture; else the default 0).
  Image anisotropy_rotation_deg;
  MapReport rotation_report;
  std::vector<ClusterFit> clusters;
  ConvergenceReport convergence;
  StageTimes times;
  FitOptions options;  // as used, for the report

  const Image& map(FitParameter p) const { return parameter_maps[static_cast<int>(p)]; }
  const MapReport& report(FitParameter p) const { return maps[static_cast<int>(p)]; }
};

// The geometry the fit needs beside the Stack (from the reconstruction): normals (3 channels, unit,
// world frame), albedo (3 channels, linear RGB, any scale; empty: estimated from the data) and
// height_mm (1 channel; empty: the sample plane z = 0). All on the stack's grid.
// fibre_turn_deg (1 channel, degrees; empty: none): each pixel's own turn of the tangent about its
// normal (shading_frame.h), the fibres' direction where the relief shows one
// (pipeline/fibre_direction.h). A cluster's anisotropy rotation is then fitted on top of it, and
// the rotation map holds their sum per pixel.
// fine_normals (3 channels, unit, world frame; empty: none) on a grid `fine_factor` (2 ..
// kMaxFacetFactor) times finer than the stack's, cell (col, row) covering fine pixels
// [fine_factor col, fine_factor (col + 1)) x [fine_factor row, ...): every observation is then
// modelled as the mixture of those facets as its camera sees them (fitting/facet_mixture.h), each
// facet keeping its tilt from the pixel's normal when the fit refines that.
struct SurfaceGeometry {
  Image normals;
  Image albedo;
  Image height_mm;
  Image fibre_turn_deg;
  Image fine_normals;
  int fine_factor = 1;
};

// Fits the maps. Throws std::invalid_argument when the inputs do not match (sizes, indices,
// options); never returns NaN: a cluster whose solve fails keeps its grid start, flagged in
// `convergence`.
FitResult FitPrincipled(const Stack& stack, const SurfaceGeometry& geometry, const FitOptions& options,
                        const ProgressCallback& progress = {});

// Renders observation `observation_index` of `stack` (its light, view, irradiance and grid; its rgb
// is ignored) with the fitted maps, for held-out checks: 3-channel linear RGB in the Stack's units.
Image RenderFitted(const FitResult& result, const Stack& stack, const SurfaceGeometry& geometry,
                   const Observation& observation);

}  // namespace u3mscan::fitting
