#pragma once
// Photometric stereo: a calibrated Stack -> per-pixel unit normal (world frame), linear RGB albedo,
// confidence and the condition number of each pixel's light system.
//
// Model (docs/capture-format.md, core/stack.h): an observation is rgb_k = rho / pi * max(0, n . l_k)
// * E_k with l_k the unit vector toward light k and E_k its relative irradiance at the surface
// point (1 for a directional light; profile / d^2, or the measured flat-field irradiance, for a
// point light). With s_k = E_k l_k the equations s_k . b = rgb_k are linear in b = rho / pi * n, one
// 3x3 system per pixel shared by the three colour channels. albedo = rho is the Lambertian
// reflectance (0..1 for a physical surface) in linear RGB.
//
// Near point lights: s_k depends on the surface point, hence on the height. The solve starts on the
// plane z = 0, integrates the normals (normal_integration.h), recomputes s_k at the new heights and
// repeats until the normals stop changing.
//
// Algorithms, stability rules and measured accuracy: docs/reconstruction.md.

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "core/image.h"
#include "core/progress.h"
#include "core/stack.h"
#include "reconstruction/normal_integration.h"
#include "reconstruction/robust_loss.h"

namespace u3mscan::reconstruction {

// The diffuse reflectance the solve assumes. Fabric is rough and the product's BRDF is the
// Principled one, whose diffuse lobe (Burley 2012) is rho / pi * (1 + (fd90 - 1) SW(cos_l)) *
// (1 + (fd90 - 1) SW(cos_v)) with SW(c) = (1 - c)^5, fd90 = 0.5 + 2 r cos_d^2 (r roughness, cos_d
// between light and half vector): at r = 1 a facet turned away from a 30 deg light looks up to
// 60 % brighter than Lambert's law says, and a Lambertian solve flattens every normal by ~10 %.
enum class DiffuseModel {
  kLambert,  // rho / pi * cos: the classic model
  kBurley,   // the Principled diffuse lobe above, by re-weighting: divide each observation by the
             // lobe's factor at the current normal and solve again (diffuse_iterations rounds)
};
std::string DiffuseModelName(DiffuseModel model);
DiffuseModel ParseDiffuseModel(const std::string& name);  // "lambert" / "burley"

enum class PsSolver {
  kLeastSquares,  // every unflagged observation, equal weights: the classic baseline
  kRobust,        // shadows, saturation and highlights as outliers: band selection, then IRLS
};

// "ls" / "robust"; ParsePsSolver throws std::invalid_argument for another name.
std::string PsSolverName(PsSolver solver);
PsSolver ParsePsSolver(const std::string& name);

struct PhotometricStereoOptions {
  PsSolver solver = PsSolver::kRobust;
  // Observations of this view only (index into Stack::views); -1 = every view (a Lambertian
  // surface looks the same from each).
  int view = -1;

  DiffuseModel diffuse_model = DiffuseModel::kBurley;
  // kBurley: the roughness r of the lobe; < 0 = estimated from the data (the r of a grid over
  // [0, 1], refined by a parabola, whose solve leaves the least residual on a sample of pixels;
  // Lambert's law instead when it leaves less).
  double diffuse_roughness = -1.0;
  // kBurley: re-weighting rounds after the first solve (the factor changes slowly with n: the
  // normal moves by < 0.01 deg after 3 rounds).
  int diffuse_iterations = 3;

  // Shading rgb / E (= rho / pi * cos) at or below this is no data: shadow or black. Units of
  // reflectance / pi; 1e-4 is ~0.03 % reflectance at normal incidence.
  double dark_shading = 1e-4;
  // kRobust: band selection for the first estimate: the darkest and brightest fractions of a
  // pixel's observations (by shading) are left out, as long as at least 4 stay.
  double band_low_fraction = 0.4;
  double band_high_fraction = 0.2;
  // kRobust: IRLS on all observations from the band estimate; weights from the residual (worst
  // channel, in shading units) over sigma = max(QuantileToSigma(q) * q-quantile of |residual|, min_residual_fraction * |b|)
  // (q = 0.5 is the classic 1.4826 MAD).
  RobustLoss loss = RobustLoss::kTukey;
  double residual_quantile = 0.35;
  int irls_iterations = 15;
  double min_residual_fraction = 0.01;

  // Stability. Condition number = sqrt(lambda_max / lambda_min) of the weighted light system
  // sum_k w_k s_k s_k^T. At or below good_condition the lights are fine; at or above
  // max_condition the pixel is ill-conditioned: low confidence, normal regularised toward its
  // neighbours.
  double good_condition = 8.0;
  double max_condition = 100.0;
  // Condition numbers are reported up to this value (no Inf in the map).
  double max_reported_condition = 1e6;
  // Albedo (grey, 0..1) below this is "near zero": the normal is too noisy to trust.
  double reliable_albedo = 0.02;
  // Normals flatter than this n_z are clamped to it (a height field seen from above cannot face
  // sideways or away); confidence drops with the clamp.
  double min_normal_z = 0.05;
  // Relative RMS fit residual (in units of the albedo) at which the confidence halves.
  double residual_tolerance = 0.05;
  // Weight of the neighbour prior for ill-conditioned pixels, relative to the largest eigenvalue
  // of their light system (Tikhonov regularisation toward rho * n_prior).
  double regularisation = 0.1;
  // Pixels whose own confidence is below this are regularised the same way (e.g. grazing lights
  // that leave a few nearly coplanar ones after shadows: n flips toward the horizon).
  double regularise_below_confidence = 0.1;

  // Near point lights: height refinement stops when the mean change of the normals between two
  // rounds is below this, or after max_near_iterations rounds.
  int max_near_iterations = 8;
  double near_tolerance_deg = 0.01;
  // How the heights are integrated between rounds, and where they are anchored (mean height of
  // the valid pixels above the sample plane z = 0, mm).
  IntegrationOptions integration;
  // Skip the refinement (the solve stays on the plane z = 0): the plain near-light model.
  bool refine_height = true;

  bool Check() const;
};

struct PhotometricStereoResult {
  Image normal;            // 3 channels, unit, world frame; always finite
  Image albedo;            // 3 channels, linear RGB Lambertian reflectance (>= 0)
  Image confidence;        // 1 channel, 0..1
  Image condition_number;  // 1 channel, >= 1, capped at max_reported_condition
  Image used_lights;       // 1 channel, number of observations with weight > 0.5 per pixel
  Image height_mm;         // 1 channel, the integrated height the near-light model used; empty for distant lights

  long long ill_conditioned_pixels = 0;  // fewer than 3 usable lights or condition >= max_condition
  long long dark_pixels = 0;             // no usable observation at all
  long long low_albedo_pixels = 0;       // albedo below reliable_albedo
  long long clamped_normal_pixels = 0;   // n_z clamped to min_normal_z
  long long regularised_pixels = 0;      // normal pulled toward the neighbours
  long long kept_pixels = 0;             // estimate kept from an earlier solve (SolvePhotometricStereoAgain)
  int near_iterations = 0;               // height refinement rounds run (0 for distant lights)
  double diffuse_roughness = -1.0;       // the Burley roughness used (given or estimated); -1: Lambert's law
  double last_normal_change_deg = 0.0;   // mean normal change of the last refinement round
  // Per pixel, how it was solved (bits private to photometric_stereo.cc): what
  // SolvePhotometricStereoAgain needs to know of a previous solve. One byte a pixel.
  std::vector<std::uint8_t> pixel_states;
};

// Throws std::invalid_argument when the stack is inconsistent (image sizes, light or view indices,
// flags size) or options fail Check().
PhotometricStereoResult RunPhotometricStereo(const Stack& stack, const PhotometricStereoOptions& options,
                                             const ProgressCallback& progress = {});

// kBurley: the diffuse roughness RunPhotometricStereo chooses for this stack (options.diffuse_roughness
// when given, else the least-residual estimate at the anchor plane, mean_height_mm); -1 when the
// model is kLambert or Lambert's law fits better. The tiled pipeline estimates it once on its
// decimated sample and passes it to every band, so that bands agree with each other and with a
// one-band run.
double ChooseDiffuseRoughness(const Stack& stack, const PhotometricStereoOptions& options);

// One solve with every pixel at the given height (1 channel on the grid, mm), no refinement: the
// step RunPhotometricStereo repeats, for callers that integrate the heights themselves (the tiled
// pipeline solves band by band and integrates the whole map between rounds). height_mm is left
// empty in the result. kBurley uses options.diffuse_roughness when given (>= 0), else estimates
// it on this stack (ChooseDiffuseRoughness). Throws like RunPhotometricStereo, and when height_mm
// is not on the grid.
PhotometricStereoResult SolvePhotometricStereoAt(const Stack& stack, const PhotometricStereoOptions& options,
                                                 const Image& height_mm);

// SolvePhotometricStereoAt after some observations were newly flagged `changed_flag` (the cast
// shadows, marked from the heights of `previous`): `previous` is the solve of the same stack, with
// the same options, before those flags were set. A pixel none of whose observations carries the
// flag, and that `previous` solved on its own data (not regularised toward its neighbours), keeps
// its estimate from `previous`: its data and its solve are the same. Every other pixel is solved
// again at height_mm, the regularised ones after the others as always (their neighbours may have
// moved). Distant lights only (with point lights the irradiance moves with the height; throws
// std::invalid_argument). The kept pixels stay at `previous`'s height, which for distant lights
// only turns the view direction that the Burley lobe reads, by about the height over the camera's
// distance (0.1 mm at 300 mm: 0.02 deg of view). Throws like SolvePhotometricStereoAt, and when
// `previous` is not a solve of this grid.
PhotometricStereoResult SolvePhotometricStereoAgain(const Stack& stack, const PhotometricStereoOptions& options,
                                                    const Image& height_mm, const PhotometricStereoResult& previous,
                                                    std::uint8_t changed_flag);

// Mean angle (degrees) between two normal maps of the same size (3 channels), over every pixel:
// how far a refinement round moved the normals.
double MeanNormalAngleDeg(const Image& a, const Image& b);

// The near-light height refinement from a first solve `result`: integrate its normals (confidence as
// weights, options.integration at pitch_mm), call at_height(height, false) (a caller may renew
// per-height data there: the shadow marks), solve_at(height), and repeat until the mean normal
// change is below options.near_tolerance_deg or after options.max_near_iterations rounds. A round
// that changes the normals more than the one before is rejected (not converging): the previous
// round is kept and at_height(its height, true) is called, so that what the caller renewed can
// match the result again (the first round is never rejected, so a kept round always exists).
// Fills height_mm, near_iterations and last_normal_change_deg of the result.
// Used by RunPhotometricStereo, the cast-shadow marking and the banded pipeline (one sweep of
// every band per solve_at).
using AtRefinementHeight = std::function<void(const Image& height_mm, bool kept_round)>;
PhotometricStereoResult RefineNearLightHeights(PhotometricStereoResult result, const PhotometricStereoOptions& options,
                                               double pitch_mm,
                                               const std::function<PhotometricStereoResult(const Image&)>& solve_at,
                                               const AtRefinementHeight& at_height, const ProgressCallback& progress = {});

}  // namespace u3mscan::reconstruction
