#include "fitting/principled_fit.h"
#include "fitting/cluster_fit.h"
#include "fitting/facet_mixture.h"
#include "fitting/grid_start.h"
#include "fitting/map_rules.h"
#include "fitting/tiled_fit.h"

#include <ceres/ceres.h>

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <memory>
#include <mutex>
#include <optional>
#include <stdexcept>

#include "core/elapsed.h"
#include "core/logging.h"
#include "core/parallel.h"
#include "fitting/shading_frame.h"

namespace u3mscan::fitting {
namespace {

// Pixels of the observation image sampled for its median luminance (the noise floor level).
constexpr int kLevelSamples = 4096;
// Smallest sigma of an observation channel, relative to its level: keeps weights finite when the
// noise floor is 0 and a value is 0.
constexpr double kMinSigmaFraction = 1e-6;
// Normals whose length is outside this band are missing data, not unit vectors.
constexpr double kMinNormalLength = 0.5;
constexpr double kMaxNormalLength = 1.5;
// Forward-difference step of the per-pixel Gauss-Newton Jacobian (parameter units).
constexpr double kPixelStep = 1e-4;
// Normal refinement (RefineNormal): forward-difference step of the tilt (tangent of the angle),
// Levenberg damping of the 2x2 normal equations, and the step below which it has converged.
constexpr double kNormalStep = 1e-4;
constexpr double kNormalDamping = 1e-3;
constexpr double kNormalConvergedTilt = 1e-5;
// The joint normal-and-lobe step (RefineNormalAndLobe) has converged below these steps: a tilt of
// 1e-3 (0.06 deg) and 0.003 in the lobe. Tighter (RefineNormal's 1e-5, 1e-4) ran every step on
// most pixels: the finer grid's normal refinement took 110 s instead of 69 s on a 9 MP plain scan
// for normals 0.874 deg either way (docs/fitting.md, "Normal and lobe together").
constexpr double kJointConvergedTilt = 1e-3;
constexpr double kJointConvergedLobe = 3e-3;
// Step halving of the per-pixel Gauss-Newton step stops below this fraction (2 tries: a pixel
// whose cost does not drop within them keeps the cluster value; this is the cheap stage).
constexpr double kMinStepScale = 0.3;
// Largest number of parameters the per-pixel step refines (roughness, specular).
constexpr int kMaxPixelParameters = 2;
// A per-pixel prior std below this holds the cluster's value (the pixels share it within noise).
constexpr double kMinPixelPriorStd = 1e-3;
// The spread estimate (ClusterPixelPriorStd): each sample's own value under a prior this wide (the
// parameter's whole range), in at least this many Gauss-Newton steps, from at least this many
// samples whose own std is below FitOptions::pixel_max_std (fewer: FitOptions::pixel_prior_std).
constexpr double kSpreadEstimatePriorStd = 1.0;
constexpr int kSpreadEstimateIterations = 3;
constexpr std::size_t kMinSpreadSamples = 8;

// The luminance a cluster's per-pixel colour solves start from: its samples' mean base colour's.
double StartLuminance(const ClusterFit& cluster) {
  return std::max(kMinStartLuminance, Luminance(cluster.mean_base_color));
}

// Whether the per-pixel step refines `parameter` of a cluster that measures `measured`.
bool RefinedPerPixel(const FitOptions& options, const ParameterMask& measured, int parameter) {
  if (parameter == kRoughness) return measured[kRoughness];
  if (parameter == kSpecular) return measured[kSpecular] && options.refine_specular_per_pixel;
  return false;
}

// Per-observation constants of the stack.
struct ObservationInfo {
  const Observation* observation = nullptr;
  const LightModel* light = nullptr;
  const ViewGeometry* view = nullptr;
  double level = 1.0;  // median luminance: the scale of the noise floor
};

// Everything the per-pixel gathering reads.
struct FitContext {
  const Stack* stack = nullptr;
  const SurfaceGeometry* geometry = nullptr;
  const FitOptions* options = nullptr;
  std::vector<ObservationInfo> observations;
  // Largest number of entries a pixel's observations can take (facet runs: kMaxFacets for every
  // observation when the geometry has fine normals), for buffer sizes.
  std::size_t max_entries = 0;
};

double MedianLuminance(const Observation& o, std::size_t pixel_count) {
  std::vector<float> values;
  const std::size_t step = std::max<std::size_t>(1, pixel_count / kLevelSamples);
  const auto r = o.rgb.plane(0), g = o.rgb.plane(1), b = o.rgb.plane(2);
  for (std::size_t i = 0; i < pixel_count; i += step) {
    if (!o.flags.empty() && o.flags[i] != 0) continue;
    const float lum = 0.3f * r[i] + 0.6f * g[i] + 0.1f * b[i];
    if (std::isfinite(lum) && lum > 0.0f) values.push_back(lum);
  }
  if (values.empty()) return 0.0;
  std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
  return values[values.size() / 2];
}

// Empty when `geometry`'s fine normals (if any) fit `grid` (SurfaceGeometry), else what is wrong.
std::string FineNormalsProblem(const SurfaceGeometry& geometry, const MetricGrid& grid) {
  if (geometry.fine_normals.empty()) return {};
  const int k = geometry.fine_factor;
  if (k < 2 || k > kMaxFacetFactor) return "fine_factor must be 2 .. " + std::to_string(kMaxFacetFactor);
  if (geometry.fine_normals.width() != k * grid.width || geometry.fine_normals.height() != k * grid.height ||
      geometry.fine_normals.channels() != 3) {
    return "fine_normals must be 3 channels on a grid fine_factor times the stack's (" + std::to_string(k * grid.width) +
           " x " + std::to_string(k * grid.height) + ")";
  }
  return {};
}

void ValidateInputs(const Stack& stack, const SurfaceGeometry& geometry, const FitOptions& options) {
  auto fail = [](const std::string& what) { throw std::invalid_argument("FitPrincipled: " + what); };
  if (!options.Check()) fail("invalid FitOptions (see FitOptions::Check)");
  const MetricGrid& grid = stack.grid;
  if (grid.width <= 0 || grid.height <= 0 || !(grid.pitch_mm > 0.0)) fail("stack grid is empty or has no pitch");
  auto check_image = [&](const Image& image, int channels, const char* name, bool optional) {
    if (image.empty() && optional) return;
    if (image.width() != grid.width || image.height() != grid.height || image.channels() != channels) {
      fail(std::string(name) + " must be " + std::to_string(channels) + " channels on the stack grid (" +
           std::to_string(grid.width) + " x " + std::to_string(grid.height) + ")");
    }
  };
  check_image(geometry.normals, 3, "normals", false);
  check_image(geometry.albedo, 3, "albedo", true);
  check_image(geometry.height_mm, 1, "height_mm", true);
  check_image(geometry.fibre_turn_deg, 1, "fibre_turn_deg", true);
  if (const std::string problem = FineNormalsProblem(geometry, grid); !problem.empty()) fail(problem);
  if (stack.observations.empty()) fail("stack has no observations");
  for (std::size_t i = 0; i < stack.observations.size(); ++i) {
    const Observation& o = stack.observations[i];
    const std::string name = "observation " + std::to_string(i);
    if (o.light < 0 || o.light >= static_cast<int>(stack.lights.size())) fail(name + ": light index out of range");
    if (o.view < 0 || o.view >= static_cast<int>(stack.views.size())) fail(name + ": view index out of range");
    check_image(o.rgb, 3, (name + " rgb").c_str(), false);
    check_image(o.irradiance, 1, (name + " irradiance").c_str(), true);
    if (!o.flags.empty() && o.flags.size() != o.rgb.pixel_count()) fail(name + ": flags must be empty or one per pixel");
  }
}

// The reconstruction's normal of pixel `index` (world frame, not normalised).
Eigen::Vector3d GeometryNormal(const FitContext& context, std::size_t index) {
  const Image& normals = context.geometry->normals;
  const int width = context.stack->grid.width;
  const int col = static_cast<int>(index % width);
  const int row = static_cast<int>(index / width);
  return {normals.at(0, row, col), normals.at(1, row, col), normals.at(2, row, col)};
}

// One usable observation of a pixel with everything that does not depend on the pixel's normal,
// in the world frame: RefineNormal turns these into the frame of each trial normal without reading
// the stack again.
struct WorldObservation {
  Eigen::Vector3d light_world;  // unit, from the pixel's surface point toward the light
  Eigen::Vector3d view_world;   // unit, toward the camera
  double irradiance = 1.0;      // relative irradiance before the cosine
  Eigen::Vector3d rgb;          // measurement, linear RGB
  Eigen::Vector3d weight;       // 1 / sigma per channel
  // A facet run's entry (LocalObservation): light_world and view_world turned by the facet's
  // tilt, `pixel_light` / `pixel_view` as the pixel's own normal sees them (the usable test).
  double facet_weight = 1.0;
  bool continues = false;
  Eigen::Vector3d pixel_light;
  Eigen::Vector3d pixel_view;
};

// The pixel's own turn of the tangent (degrees, SurfaceGeometry::fibre_turn_deg), 0 without one.
double PixelTurn(const FitContext& context, std::size_t index) {
  const Image& turns = context.geometry->fibre_turn_deg;
  if (turns.empty()) return 0.0;
  const double turn = turns.plane(0)[index];
  return std::isfinite(turn) ? turn : 0.0;
}

// The pixel's surface point (world, mm): the grid point raised to the reconstruction's height.
Eigen::Vector3d SurfacePoint(const FitContext& context, int col, int row) {
  const Image& height = context.geometry->height_mm;
  return context.stack->grid.PixelCentreInWorld(col, row, height.empty() ? 0.0 : height.at(0, row, col));
}

// Observation `info` of pixel `index` (at `col`, `row`, surface `point`) in the world frame; false
// when it is flagged, not finite or without irradiance.
bool WorldObservationAt(const FitContext& context, const ObservationInfo& info, std::size_t index, int col, int row,
                        const Eigen::Vector3d& point, WorldObservation* out) {
  const Observation& o = *info.observation;
  if (!o.flags.empty() && o.flags[index] != 0) return false;
  const Eigen::Vector3d rgb(o.rgb.at(0, row, col), o.rgb.at(1, row, col), o.rgb.at(2, row, col));
  if (!rgb.allFinite()) return false;
  const double e = o.irradiance.empty() ? info.light->RelativeIrradianceAt(point) : o.irradiance.at(0, row, col);
  if (!(e > 0.0) || !std::isfinite(e)) return false;
  const FitOptions& options = *context.options;
  out->light_world = info.light->DirectionFrom(point);
  out->view_world = (info.view->centre_in_world_mm - point).normalized();
  out->irradiance = e;
  out->rgb = rgb;
  out->facet_weight = 1.0;
  out->continues = false;
  out->pixel_light = out->light_world;
  out->pixel_view = out->view_world;
  const double floor = options.noise_floor * info.level;
  const double min_sigma = kMinSigmaFraction * info.level;  // noise_floor may be 0
  for (int c = 0; c < 3; ++c) out->weight(c) = 1.0 / std::max(min_sigma, floor + options.noise_relative * std::abs(rgb(c)));
  return true;
}

// The facets each view sees in one pixel (facet_mixture.h), computed once per pixel and view.
struct PixelFacetCache {
  static constexpr int kCachedViews = 8;  // views beyond these are computed for each observation
  std::array<int, kCachedViews> count;    // -1: not computed yet
  std::array<FacetSet, kCachedViews> facets;
  PixelFacetCache() { count.fill(-1); }
};

// Observation `info` of pixel `index` as world entries into `out`: one, or with fine normals (and
// then a `cache`, which is not read otherwise), a
// facet run (LocalObservation): each facet's entry has the light and view turned by
// the rotation from the pixel's normal to the facet's, so that whatever normal the fit gives the
// pixel, the facet keeps its tilt from it. Returns the entries written (0: not usable).
int WorldEntriesAt(const FitContext& context, const ObservationInfo& info, std::size_t index, int col, int row,
                   const Eigen::Vector3d& point, PixelFacetCache* cache, WorldObservation* out) {
  WorldObservation plain;
  if (!WorldObservationAt(context, info, index, col, row, point, &plain)) return 0;
  const SurfaceGeometry& geometry = *context.geometry;
  if (geometry.fine_normals.empty()) {
    out[0] = plain;
    return 1;
  }
  const int view = info.observation->view;
  FacetSet computed;
  const FacetSet* facets = &computed;
  int count = 0;
  if (view < PixelFacetCache::kCachedViews) {
    if (cache->count[view] < 0) {
      cache->count[view] = ViewFacets(geometry.fine_normals, geometry.fine_factor, col, row, plain.view_world,
                                      &cache->facets[view]);
    }
    facets = &cache->facets[view];
    count = cache->count[view];
  } else {
    count = ViewFacets(geometry.fine_normals, geometry.fine_factor, col, row, plain.view_world, &computed);
  }
  const Eigen::Vector3d n = GeometryNormal(context, index);
  const double length = n.norm();
  if (count == 0 || !(length > kMinNormalLength && length < kMaxNormalLength)) {
    out[0] = plain;
    return 1;
  }
  for (int f = 0; f < count; ++f) {
    const Eigen::Quaterniond back = TurnIntoFacet(n / length, (*facets)[f]);
    WorldObservation& entry = out[f];
    entry = plain;
    entry.light_world = back * plain.light_world;
    entry.view_world = back * plain.view_world;
    entry.facet_weight = (*facets)[f].weight;
    entry.continues = f + 1 < count;
    if (entry.continues) {
      entry.rgb.setZero();
      entry.weight.setZero();
    }
  }
  return count;
}

// `world` in the shading frame `frame`; false when the light or the camera is below `min_cos` (as
// the pixel's own normal sees them: a facet run is used or left out as a whole).
bool ToLocalObservation(const WorldObservation& world, const ShadingFrame& frame, double min_cos, LocalObservation* out) {
  if (frame.ToLocal(world.pixel_light).z() < min_cos || frame.ToLocal(world.pixel_view).z() < min_cos) return false;
  out->light_local = frame.ToLocal(world.light_world);
  out->view_local = frame.ToLocal(world.view_world);
  out->irradiance = world.irradiance;
  out->rgb = world.rgb;
  out->weight = world.weight;
  out->facet_weight = world.facet_weight;
  out->continues = world.continues;
  return true;
}

// The usable observations of pixel `index` in the world frame, into `out` (resized to the stack's
// observation count once); returns their number.
int GatherWorldObservations(const FitContext& context, std::size_t index, std::vector<WorldObservation>& out) {
  const int width = context.stack->grid.width;
  const int col = static_cast<int>(index % width);
  const int row = static_cast<int>(index / width);
  const Eigen::Vector3d point = SurfacePoint(context, col, row);
  if (out.size() < context.max_entries) out.resize(context.max_entries);
  std::optional<PixelFacetCache> facets;  // 8 views x 9 facets: built only for a pixel with facets
  if (!context.geometry->fine_normals.empty()) facets.emplace();
  int count = 0;
  for (const ObservationInfo& info : context.observations) {
    count += WorldEntriesAt(context, info, index, col, row, point, facets ? &*facets : nullptr, &out[count]);
  }
  return count;
}

// As GatherPixel, with the pixel's normal given (world frame, any length in the valid band) and
// its tangent turned by `rotation_deg` (the cluster's anisotropy rotation, shading_frame.h) on top
// of the pixel's own turn (PixelTurn).
int GatherPixelWithNormal(const FitContext& context, std::size_t index, Eigen::Vector3d n, double rotation_deg,
                          LocalObservation* out, float* ratios) {
  const int width = context.stack->grid.width;
  const int col = static_cast<int>(index % width);
  const int row = static_cast<int>(index / width);
  const double length = n.norm();
  if (!(length > kMinNormalLength && length < kMaxNormalLength)) return 0;
  n /= length;
  const ShadingFrame frame = MakeShadingFrame(n, rotation_deg + PixelTurn(context, index));
  const Eigen::Vector3d point = SurfacePoint(context, col, row);
  const double min_cos = context.options->min_cos;
  int count = 0;
  std::array<WorldObservation, kMaxFacets> entries;
  std::optional<PixelFacetCache> facets;  // as in GatherWorldObservations
  if (!context.geometry->fine_normals.empty()) facets.emplace();
  for (const ObservationInfo& info : context.observations) {
    const int entry_count =
        WorldEntriesAt(context, info, index, col, row, point, facets ? &*facets : nullptr, entries.data());
    double run_cosine = 0.0;  // the run's cos_l: its facets' cosines with their shares
    for (int e = 0; e < entry_count; ++e) {
      LocalObservation& lo = out[count];
      if (!ToLocalObservation(entries[e], frame, min_cos, &lo)) break;  // a run is usable as a whole
      run_cosine += lo.facet_weight * std::max(0.0, lo.light_local.z());
      // The ratio at the run's last entry (0 in its continued entries: they hold no data).
      if (ratios != nullptr) {
        ratios[count] = lo.continues ? 0.0f : static_cast<float>(Luminance(lo.rgb) / (run_cosine * lo.irradiance));
      }
      ++count;
    }
  }
  return count;
}

// The usable observations of pixel `index` in its reconstruction normal's frame, the tangent
// turned by the pixel's own turn only (PixelTurn); returns their number (at most
// stack.observations.size(), the size `out` must have). Also the reflectance ratios
// (luminance / (cos_l E)) into `ratios` when non-null.
int GatherPixel(const FitContext& context, std::size_t index, LocalObservation* out, float* ratios) {
  return GatherPixelWithNormal(context, index, GeometryNormal(context, index), 0.0, out, ratios);
}

// True when the `count` entries at `obs` hold at least min_observations measurements (a facet run
// counts once).
bool EnoughMeasurements(const FitContext& context, const LocalObservation* obs, int count) {
  return CountMeasurements(std::span<const LocalObservation>(obs, static_cast<std::size_t>(count))) >=
         context.options->min_observations;
}

// A pixel's world observations in the shading frame of normal `n` (turned by `turn_deg`, the
// cluster's turn on the pixel's own) written to `buffer`; returns how many are usable there.
int LocalizeObservations(std::span<const WorldObservation> world, const Eigen::Vector3d& n, double turn_deg,
                         double min_cos, LocalObservation* buffer) {
  const ShadingFrame frame = MakeShadingFrame(n, turn_deg);
  int count = 0;
  for (const WorldObservation& w : world) {
    if (ToLocalObservation(w, frame, min_cos, &buffer[count])) ++count;
  }
  return count;
}

// RefineNormal's buffers, one per worker: grown to the stack's observation count once, then reused
// (no allocation per pixel).
struct NormalRefinementScratch {
  std::vector<WorldObservation> world;
  std::vector<double> residuals;  // 4 x 3 entries: the residuals, a trial's, two Jacobian columns
};

// Refines the normal of one pixel with the full Principled model at the cluster's shared `params`
// (base colour in closed form): damped Gauss-Newton on the two tilts of the normal in the tangent
// plane of the reconstruction's normal. Photometric stereo solves a Lambertian model, so on a
// glossy fabric its normals lean toward the highlights by about a degree; fitted with those
// normals, the specular lobe is explained as a weaker, wider one (specular 0.5 -> 0.23 on the bump
// field). Returns the refined unit normal, or the reconstruction's if no step lowers the cost.
// The pixel's observations are read from the stack once (GatherWorldObservations) and turned into
// each trial normal's frame; the Jacobian is a forward difference (2 evaluations a step, not 4:
// Gauss-Newton needs its direction, not its last digit, and the accepted step is checked on the
// cost). `buffer` (FitContext::max_entries) ends holding the pixel's usable observations in the returned
// normal's frame, as GatherPixelWithNormal gives them, and `*count` their number.
Eigen::Vector3d RefineNormal(const FitContext& context, std::size_t index, const ParameterVector& params,
                             double rotation_deg, const PixelCostSettings& settings, int iterations,
                             LocalObservation* buffer, NormalRefinementScratch& scratch, int* count) {
  const FitOptions& options = *context.options;
  Eigen::Vector3d n0 = GeometryNormal(context, index);
  const double length = n0.norm();
  *count = 0;
  if (!(length > kMinNormalLength && length < kMaxNormalLength)) return n0;
  n0 /= length;
  // The two tilt directions: the unturned shading frame's tangent and bitangent.
  const ShadingFrame axes = MakeShadingFrame(n0);
  const Eigen::Vector3d& t0 = axes.tangent;
  const Eigen::Vector3d& b0 = axes.bitangent;
  const int gathered = GatherWorldObservations(context, index, scratch.world);
  const std::span<const WorldObservation> world(scratch.world.data(), gathered);
  // The observations in the frame of normal `n`; returns their number.
  const double turn_deg = rotation_deg + PixelTurn(context, index);
  auto localize = [&](const Eigen::Vector3d& n) {
    return LocalizeObservations(world, n, turn_deg, options.min_cos, buffer);
  };
  // `n` with `buffer` and `*count` set for it (normalised again, as GatherPixelWithNormal does).
  auto finish = [&](const Eigen::Vector3d& n) {
    *count = localize(n / n.norm());
    return n;
  };
  const int count0 = localize(n0);
  if (!EnoughMeasurements(context, buffer, count0)) return finish(n0);
  const std::size_t m = 3 * static_cast<std::size_t>(count0);
  scratch.residuals.resize(4 * m);
  double* r = scratch.residuals.data();
  double* trial = r + m;
  double* jac0 = r + 2 * m;
  double* jac1 = r + 3 * m;
  // Residuals at tilt (a, b); false when the set of usable observations changes.
  auto eval = [&](const Eigen::Vector2d& tilt, double* out, double* cost) {
    const Eigen::Vector3d n = (n0 + tilt(0) * t0 + tilt(1) * b0).normalized();
    if (localize(n) != count0) return false;
    *cost = PixelResiduals(params, std::span<const LocalObservation>(buffer, count0), settings, out);
    return std::isfinite(*cost);
  };
  Eigen::Vector2d tilt = Eigen::Vector2d::Zero();
  double cost = 0.0;
  if (!eval(tilt, r, &cost)) return finish(n0);
  const double max_tilt = std::tan(options.normal_max_change_deg * M_PI / 180.0);
  for (int iteration = 0; iteration < iterations; ++iteration) {
    bool ok = true;
    for (int j = 0; j < 2 && ok; ++j) {
      Eigen::Vector2d step = Eigen::Vector2d::Zero();
      step(j) = kNormalStep;
      double stepped_cost = 0.0;
      ok = eval(tilt + step, trial, &stepped_cost);
      double* column = j == 0 ? jac0 : jac1;
      for (std::size_t i = 0; ok && i < m; ++i) column[i] = (trial[i] - r[i]) / kNormalStep;
    }
    if (!ok) break;
    Eigen::Matrix2d jtj = Eigen::Matrix2d::Zero();
    Eigen::Vector2d jtr = Eigen::Vector2d::Zero();
    for (std::size_t i = 0; i < m; ++i) {
      const Eigen::Vector2d g(jac0[i], jac1[i]);
      jtj += g * g.transpose();
      jtr += g * r[i];
    }
    jtj.diagonal() *= 1.0 + kNormalDamping;
    const Eigen::Vector2d delta = jtj.ldlt().solve(-jtr);
    if (!delta.allFinite()) break;
    bool accepted = false;
    for (double scale = 1.0; scale >= kMinStepScale; scale *= 0.5) {
      Eigen::Vector2d candidate = tilt + scale * delta;
      if (candidate.norm() > max_tilt) candidate *= max_tilt / candidate.norm();
      double candidate_cost = 0.0;
      if (eval(candidate, trial, &candidate_cost) && candidate_cost < cost) {
        tilt = candidate;
        cost = candidate_cost;
        std::copy(trial, trial + m, r);
        accepted = true;
        break;
      }
    }
    if (!accepted || delta.norm() < kNormalConvergedTilt) break;
  }
  return finish((n0 + tilt(0) * t0 + tilt(1) * b0).normalized());
}

// Albedo of a pixel for clustering: the reconstruction's, else the per-channel median ratio.
void PixelAlbedo(const FitContext& context, std::size_t index, const LocalObservation* obs, int count,
                 float* scratch, float albedo[3]) {
  const Image& image = context.geometry->albedo;
  if (!image.empty()) {
    const int width = context.stack->grid.width;
    for (int c = 0; c < 3; ++c) albedo[c] = image.at(c, static_cast<int>(index / width), static_cast<int>(index % width));
    return;
  }
  for (int c = 0; c < 3; ++c) {
    int measured = 0;  // one ratio per measurement, with a facet run's cosine (GatherPixelWithNormal)
    double run_cosine = 0.0;
    for (int i = 0; i < count; ++i) {
      run_cosine += obs[i].facet_weight * std::max(0.0, obs[i].light_local.z());
      if (obs[i].continues) continue;
      scratch[measured++] = static_cast<float>(obs[i].rgb(c) / (run_cosine * obs[i].irradiance));
      run_cosine = 0.0;
    }
    std::nth_element(scratch, scratch + measured / 2, scratch + measured);
    albedo[c] = measured > 0 ? scratch[measured / 2] : 0.0f;
  }
}

// Per-worker buffers, allocated once per chunk of pixels.
struct PixelBuffers {
  std::vector<LocalObservation> observations;
  std::vector<float> ratios;
  std::vector<float> scratch;
  explicit PixelBuffers(std::size_t n) : observations(n), ratios(n), scratch(n) {}
};

// Gathers a pixel and computes its appearance features (when it has enough measurements, which
// `*enough` says); returns the number of entries gathered.
int PixelFeatures(const FitContext& context, std::size_t index, PixelBuffers& buffers, float* features, bool* enough) {
  const int count = GatherPixel(context, index, buffers.observations.data(), buffers.ratios.data());
  *enough = EnoughMeasurements(context, buffers.observations.data(), count);
  if (!*enough) return count;
  float albedo[3];
  PixelAlbedo(context, index, buffers.observations.data(), count, buffers.scratch.data(), albedo);
  // One ratio per measurement: a facet run's continued entries hold no data.
  int measured = 0;
  for (int i = 0; i < count; ++i) {
    if (!buffers.observations[i].continues) buffers.scratch[measured++] = buffers.ratios[i];
  }
  AppearanceFeatures(albedo, std::span<float>(buffers.scratch.data(), measured), features);
  return count;
}

// The lobe parameters the per-pixel step refines (roughness, specular: RefinedPerPixel, with a
// prior std of at least kMinPixelPriorStd) and their prior weights 1 / std^2.
struct PixelLobe {
  int parameter[kMaxPixelParameters];
  double prior_weight[kMaxPixelParameters];
  int count = 0;
};
PixelLobe PixelLobeParameters(const FitOptions& options, const ParameterMask& measured, const ParameterVector& prior_std) {
  PixelLobe lobe;
  for (int parameter : {kRoughness, kSpecular}) {
    if (!RefinedPerPixel(options, measured, parameter) || !(prior_std[parameter] >= kMinPixelPriorStd)) continue;
    lobe.prior_weight[lobe.count] = 1.0 / (prior_std[parameter] * prior_std[parameter]);
    lobe.parameter[lobe.count++] = parameter;
  }
  return lobe;
}

// Gauss-Newton's system from forward-difference columns: J^T J into the top-left `n` x `n` of `*h`
// and J^T r into the first `n` entries of `*g` (column j of J at jac + j * m, m residuals `r`).
template <typename Matrix, typename Vector>
void AccumulateGaussNewton(const double* jac, const double* r, std::size_t m, int n, Matrix* h, Vector* g) {
  for (int a = 0; a < n; ++a) {
    for (int b = 0; b <= a; ++b) {
      double sum = 0.0;
      for (std::size_t i = 0; i < m; ++i) sum += jac[a * m + i] * jac[b * m + i];
      (*h)(a, b) = (*h)(b, a) = sum;
    }
    double sum = 0.0;
    for (std::size_t i = 0; i < m; ++i) sum += jac[a * m + i] * r[i];
    (*g)(a) = sum;
  }
}

// Per-pixel refinement of roughness / specular toward the pixel's own data, regularised toward the
// cluster value with prior std `prior_std[parameter]` (a parameter whose prior std is below
// kMinPixelPriorStd keeps the cluster value). Damped Gauss-Newton with forward differences;
// residual buffers come from the caller. Returns how many parameters were kept; their posterior
// std goes to (*kept_sd)[parameter] (others untouched). `color` receives the closed-form base
// colour at the returned parameters (saves a solve).
int RefinePixel(std::span<const LocalObservation> obs, const FitOptions& options, const ParameterMask& measured,
                const ParameterVector& prior_std, double luminance_start, const ParameterVector& cluster,
                ParameterVector& params, std::vector<double>& r0, std::vector<double>& r1, std::vector<double>& jac,
                Eigen::Vector3d* color, ParameterVector* kept_sd) {
  const PixelLobe refined = PixelLobeParameters(options, measured, prior_std);
  const int* index = refined.parameter;
  const double* prior_w = refined.prior_weight;
  const int k = refined.count;
  const PixelCostSettings settings = CostSettingsFor(options, cluster, measured, luminance_start);
  if (k == 0) {
    *color = SolveBaseColor(params, obs, settings);
    return 0;
  }
  const std::size_t m = 3 * obs.size();
  r0.resize(m);
  r1.resize(m);
  jac.resize(m * k);
  auto total = [&](const ParameterVector& p, std::vector<double>& r, Eigen::Vector3d* c_out) {
    double c = PixelResiduals(p, obs, settings, r.data(), c_out);
    for (int a = 0; a < k; ++a) c += 0.5 * prior_w[a] * (p[index[a]] - cluster[index[a]]) * (p[index[a]] - cluster[index[a]]);
    return c;
  };
  // Fixed-size normal equations (no allocation per pixel); unused rows are identity.
  using Matrix2 = Eigen::Matrix<double, kMaxPixelParameters, kMaxPixelParameters>;
  using Vector2 = Eigen::Matrix<double, kMaxPixelParameters, 1>;
  Matrix2 h = Matrix2::Identity();
  double cost = total(params, r0, color);
  const ParameterVector start = params;
  const Eigen::Vector3d start_color = *color;
  for (int it = 0; it < options.pixel_iterations; ++it) {
    for (int a = 0; a < k; ++a) {
      ParameterVector q = params;
      const double step = q[index[a]] + kPixelStep <= 1.0 ? kPixelStep : -kPixelStep;
      q[index[a]] += step;
      PixelResiduals(q, obs, settings, r1.data());
      for (std::size_t i = 0; i < m; ++i) jac[a * m + i] = (r1[i] - r0[i]) / step;
    }
    h.setIdentity();
    Vector2 g = Vector2::Zero();
    AccumulateGaussNewton(jac.data(), r0.data(), m, k, &h, &g);
    for (int a = 0; a < k; ++a) {
      g(a) += prior_w[a] * (params[index[a]] - cluster[index[a]]);
      h(a, a) += prior_w[a];
    }
    // No step where even the best case cannot pin the value down (cheap stage: skip early).
    const Matrix2 covariance = h.inverse();
    bool supported = false;
    for (int a = 0; a < k; ++a) supported = supported || std::sqrt(std::max(0.0, covariance(a, a))) < options.pixel_max_std;
    if (!supported) break;
    const Vector2 delta = -h.ldlt().solve(g);
    if (!delta.allFinite()) break;
    // Step halving keeps the damped step a descent step.
    bool accepted = false;
    for (double scale = 1.0; scale > kMinStepScale && !accepted; scale *= 0.5) {
      ParameterVector q = params;
      for (int a = 0; a < k; ++a) q[index[a]] = std::clamp(q[index[a]] + scale * delta(a), 0.0, 1.0);
      Eigen::Vector3d c_color;
      const double c = total(q, r1, &c_color);
      if (c < cost) {
        *color = c_color;
        params = q;
        cost = c;
        std::swap(r0, r1);
        accepted = true;
      }
    }
    if (!accepted) break;
  }
  // Keep a refined value only where the pixel's own data pins it down. The covariance comes from
  // the last linearisation (identity rows unused), inflated by the pixel's reduced chi^2 when the
  // noise model underestimates its scatter (as for the clusters).
  const Matrix2 covariance = h.inverse();
  double chi2 = 0.0;
  for (std::size_t i = 0; i < m; ++i) chi2 += r0[i] * r0[i];
  const double inflation = m > static_cast<std::size_t>(k) ? std::max(1.0, chi2 / static_cast<double>(m - k)) : 1.0;
  int kept = 0;
  for (int a = 0; a < k; ++a) {
    const double sd = std::sqrt(std::max(0.0, covariance(a, a)) * inflation);
    if (std::isfinite(sd) && sd < options.pixel_max_std) {
      ++kept;
      (*kept_sd)[index[a]] = sd;
    } else {
      params[index[a]] = cluster[index[a]];
    }
  }
  if (kept < k && params != start) {
    *color = SolveBaseColor(params, obs, settings);  // a partial revert changes the colour
  } else if (params == start) {
    *color = start_color;
  }
  return kept;
}

// The pixel's normal and its lobe together (FitOptions::refine_normal_with_lobe): damped
// Gauss-Newton on the two tilts of the normal in the tangent plane of `n_start` (the normal
// RefineNormal gave at the cluster's lobe) and on the lobe parameters RefinePixel refines, each
// regularised toward the cluster's value with the cluster's prior std. Forward differences as in
// both (the tilt columns turn the observations into the trial normal's frame). Succeeds when every
// lobe parameter's posterior std, the tilts marginalised and the covariance inflated by the
// pixel's reduced chi^2, is below pixel_max_std: then `*params` holds the pixel's lobe, `*color`
// its closed-form base colour, `*kept_sd` the lobe's std, and the joint normal is returned.
// Otherwise returns `n_start` with `*params` untouched. Either way `buffer` ends holding the pixel's
// usable observations in the returned normal's frame and `*count` their number.
Eigen::Vector3d RefineNormalAndLobe(const FitContext& context, std::size_t index, const Eigen::Vector3d& n_start,
                                    const ParameterMask& measured, const ParameterVector& prior_std,
                                    const ParameterVector& cluster, double rotation_deg,
                                    const PixelCostSettings& settings, LocalObservation* buffer,
                                    NormalRefinementScratch& scratch, int* count, ParameterVector* params,
                                    Eigen::Vector3d* color, ParameterVector* kept_sd, bool* succeeded) {
  const FitOptions& options = *context.options;
  *succeeded = false;
  constexpr int kMaxUnknowns = 2 + kMaxPixelParameters;
  const PixelLobe refined = PixelLobeParameters(options, measured, prior_std);
  const int* lobe = refined.parameter;
  const double* prior_w = refined.prior_weight;
  const int k = refined.count;
  const ShadingFrame axes = MakeShadingFrame(n_start);
  const int gathered = GatherWorldObservations(context, index, scratch.world);
  const std::span<const WorldObservation> world(scratch.world.data(), gathered);
  const double turn_deg = rotation_deg + PixelTurn(context, index);
  auto localize = [&](const Eigen::Vector3d& n) {
    return LocalizeObservations(world, n, turn_deg, options.min_cos, buffer);
  };
  auto normal_at = [&](const Eigen::Vector2d& tilt) {
    return (n_start + tilt(0) * axes.tangent + tilt(1) * axes.bitangent).normalized();
  };
  const int count0 = localize(n_start);
  *count = count0;
  if (k == 0 || !EnoughMeasurements(context, buffer, count0) || count0 < 2 * kMaxUnknowns) return n_start;
  const std::size_t m = 3 * static_cast<std::size_t>(count0);
  const int unknowns = 2 + k;
  scratch.residuals.resize((2 + kMaxUnknowns) * m);
  double* r = scratch.residuals.data();
  double* trial = r + m;
  double* jac = r + 2 * m;  // column j at jac + j * m
  // Cost (data plus the lobe's prior) at tilt and lobe `p`; false when the set of usable
  // observations changes (as RefineNormal).
  auto eval = [&](const Eigen::Vector2d& tilt, const ParameterVector& p, double* out, double* cost,
                  Eigen::Vector3d* c_out) {
    if (localize(normal_at(tilt)) != count0) return false;
    double c = PixelResiduals(p, std::span<const LocalObservation>(buffer, count0), settings, out, c_out);
    for (int a = 0; a < k; ++a) c += 0.5 * prior_w[a] * (p[lobe[a]] - cluster[lobe[a]]) * (p[lobe[a]] - cluster[lobe[a]]);
    *cost = c;
    return std::isfinite(c);
  };
  using Matrix = Eigen::Matrix<double, kMaxUnknowns, kMaxUnknowns>;
  using Vector = Eigen::Matrix<double, kMaxUnknowns, 1>;
  Eigen::Vector2d tilt = Eigen::Vector2d::Zero();
  ParameterVector p = *params;
  double cost = 0.0;
  Eigen::Vector3d c_color;
  auto give_up = [&]() {
    *count = localize(n_start);
    return n_start;
  };
  if (!eval(tilt, p, r, &cost, &c_color)) return give_up();
  const double max_tilt = std::tan(options.normal_max_change_deg * M_PI / 180.0);
  Matrix h = Matrix::Identity();
  bool linearised = false;
  for (int iteration = 0; iteration < options.pixel_joint_iterations; ++iteration) {
    bool ok = true;
    double unused = 0.0;
    for (int j = 0; j < unknowns && ok; ++j) {
      Eigen::Vector2d t = tilt;
      ParameterVector q = p;
      double step = kNormalStep;
      if (j < 2) {
        t(j) += step;
      } else {
        step = q[lobe[j - 2]] + kPixelStep <= 1.0 ? kPixelStep : -kPixelStep;
        q[lobe[j - 2]] += step;
      }
      ok = eval(t, q, trial, &unused, nullptr);
      for (std::size_t i = 0; ok && i < m; ++i) jac[j * m + i] = (trial[i] - r[i]) / step;
    }
    if (!ok) break;
    h.setIdentity();
    Vector g = Vector::Zero();
    AccumulateGaussNewton(jac, r, m, unknowns, &h, &g);
    for (int a = 0; a < k; ++a) {
      g(2 + a) += prior_w[a] * (p[lobe[a]] - cluster[lobe[a]]);
      h(2 + a, 2 + a) += prior_w[a];
    }
    linearised = true;
    Matrix damped = h;
    for (int a = 0; a < 2; ++a) damped(a, a) *= 1.0 + kNormalDamping;
    const Vector delta = -damped.ldlt().solve(g);
    if (!delta.allFinite()) break;
    bool accepted = false;
    for (double scale = 1.0; scale >= kMinStepScale && !accepted; scale *= 0.5) {
      Eigen::Vector2d t = tilt + scale * delta.head<2>();
      if (t.norm() > max_tilt) t *= max_tilt / t.norm();
      ParameterVector q = p;
      for (int a = 0; a < k; ++a) q[lobe[a]] = std::clamp(q[lobe[a]] + scale * delta(2 + a), 0.0, 1.0);
      double candidate = 0.0;
      Eigen::Vector3d candidate_color;
      if (eval(t, q, trial, &candidate, &candidate_color) && candidate < cost) {
        tilt = t;
        p = q;
        cost = candidate;
        c_color = candidate_color;
        std::copy(trial, trial + m, r);
        accepted = true;
      }
    }
    double lobe_step = 0.0;
    for (int a = 0; a < k; ++a) lobe_step = std::max(lobe_step, std::abs(delta(2 + a)));
    if (!accepted || (delta.head<2>().norm() < kJointConvergedTilt && lobe_step < kJointConvergedLobe)) break;
  }
  if (!linearised) return give_up();
  // The lobe's std with the tilts marginalised: the lobe block of the inverse of the last
  // linearisation, inflated by the reduced chi^2 (as RefinePixel).
  Matrix used = Matrix::Identity();
  used.topLeftCorner(unknowns, unknowns) = h.topLeftCorner(unknowns, unknowns);
  const Matrix covariance = used.inverse();
  double chi2 = 0.0;
  for (std::size_t i = 0; i < m; ++i) chi2 += r[i] * r[i];
  const double inflation = std::max(1.0, chi2 / static_cast<double>(m - unknowns));
  ParameterVector sd = *kept_sd;
  for (int a = 0; a < k; ++a) {
    const double s = std::sqrt(std::max(0.0, covariance(2 + a, 2 + a)) * inflation);
    if (!(std::isfinite(s) && s < options.pixel_max_std)) return give_up();
    sd[lobe[a]] = s;
  }
  *params = p;
  *color = c_color;
  *kept_sd = sd;
  *succeeded = true;
  const Eigen::Vector3d n = normal_at(tilt);
  *count = localize(n);
  return n;
}

// ClusterFit::pixel_prior_std of a cluster at its final `params` (empirical Bayes): how far its
// pixels' own values spread beyond their noise. Each sample's value x and std s come from
// RefinePixel under a prior too wide to matter; a sample counts where s < options.pixel_max_std
// (where the per-pixel step would keep its value). The spread is sqrt(max(0, mean((x - value)^2 -
// s^2))), at most options.pixel_prior_std; with fewer than kMinSpreadSamples such samples, or with
// options.pixel_prior_from_samples off, options.pixel_prior_std. Why: one prior for every cluster
// either writes a uniform fabric's noise into its map (plain, velvet at 4x) or holds a fabric whose
// threads differ back to the cluster's value (denim's warp, 0.74-0.96).
ParameterVector ClusterPixelPriorStd(const ClusterSamples& samples, const ParameterVector& params,
                                     const ParameterMask& measured, double luminance_start, const FitOptions& options) {
  ParameterVector prior{};
  for (int i = 0; i < kFitParameterCount; ++i) prior[i] = RefinedPerPixel(options, measured, i) ? options.pixel_prior_std : 0.0;
  if (!options.pixel_prior_from_samples || options.mode != FitMode::kPerPixel) return prior;
  FitOptions wide = options;
  wide.pixel_prior_std = kSpreadEstimatePriorStd;
  wide.pixel_max_std = std::numeric_limits<double>::infinity();
  wide.pixel_iterations = std::max(options.pixel_iterations, kSpreadEstimateIterations);
  ParameterVector wide_prior{};
  for (int i = 0; i < kFitParameterCount; ++i) wide_prior[i] = prior[i] > 0.0 ? kSpreadEstimatePriorStd : 0.0;
  std::vector<double> r0, r1, jac;
  ParameterVector excess{};  // sum of (x - value)^2 - s^2
  std::array<std::size_t, kFitParameterCount> counted{};
  for (std::size_t p = 0; p < samples.pixels(); ++p) {
    const std::span<const LocalObservation> obs = samples.pixel(p);
    if (CountMeasurements(obs) < 2 * kMaxPixelParameters) continue;
    ParameterVector x = params;
    ParameterVector sd;
    sd.fill(-1.0);
    Eigen::Vector3d color;
    RefinePixel(obs, wide, measured, wide_prior, luminance_start, params, x, r0, r1, jac, &color, &sd);
    for (int i = 0; i < kFitParameterCount; ++i) {
      if (!(sd[i] >= 0.0) || !(sd[i] < options.pixel_max_std)) continue;
      excess[i] += (x[i] - params[i]) * (x[i] - params[i]) - sd[i] * sd[i];
      ++counted[i];
    }
  }
  for (int i = 0; i < kFitParameterCount; ++i) {
    if (prior[i] == 0.0 || counted[i] < kMinSpreadSamples) continue;
    prior[i] = std::min(options.pixel_prior_std, std::sqrt(std::max(0.0, excess[i] / static_cast<double>(counted[i]))));
  }
  return prior;
}

}  // namespace

const char* FitModeName(FitMode mode) { return mode == FitMode::kClusters ? "clusters" : "per-pixel"; }

FitMode ParseFitMode(const std::string& name) {
  if (name == "clusters") return FitMode::kClusters;
  if (name == "per-pixel") return FitMode::kPerPixel;
  throw std::invalid_argument("fit mode must be clusters or per-pixel, got '" + name + "'");
}

const char* U3mParameterName(FitParameter parameter) {
  switch (parameter) {
    case FitParameter::kRoughness: return "roughness";
    case FitParameter::kSpecular: return "specular_value";
    case FitParameter::kSpecularTint: return "specular_tint";
    case FitParameter::kSheen: return "sheen_value";
    case FitParameter::kSheenTint: return "sheen_tint";
    case FitParameter::kAnisotropic: return "anisotropy_value";
    case FitParameter::kMetallic: return "metalness";
  }
  throw std::logic_error("U3mParameterName: unknown parameter");
}

bool FitOptions::Check() const {
  return clustering.Check() && observability.Check() && samples_per_cluster >= 1 && grid_samples_per_cluster >= 1 &&
         noise_relative >= 0.0 && noise_floor >= 0.0 && noise_relative + noise_floor > 0.0 && robust_loss.scale > 0.0 &&
         min_cos >= 0.0 && min_cos < 1.0 && min_observations >= 1 && max_iterations >= 1 && luminance_passes >= 1 &&
         mismatch_relative_rms > 0.0 && unusable_relative_rms >= mismatch_relative_rms && pixel_prior_std > 0.0 && pixel_max_std > 0.0 && pixel_min_specular_fraction >= 0.0 &&
         pixel_min_specular_fraction < 1.0 && pixel_iterations >= 0 && normal_refinement_max_passes >= 0 && normal_refinement_tolerance_deg >= 0.0 &&
         normal_iterations >= 1 && pixel_normal_iterations >= 1 && pixel_joint_iterations >= 1 &&
         normal_max_change_deg > 0.0 && normal_max_change_deg < 90.0 && min_highlight_share >= 0.0 &&
         min_highlight_share <= 1.0 && highlight_lobe_fraction > 0.0 && highlight_lobe_fraction < 1.0 &&
         unreliable_pixel_share >= 0.0 && unreliable_pixel_share < 1.0;
}

// Per-observation constants of `stack` with the given noise levels (MedianLuminance of the stack
// itself when `levels` is empty: an observation without signal borrows the typical level, so that
// its noise floor, and with it every weight, stays finite).
namespace {
FitContext MakeContext(const Stack& stack, const SurfaceGeometry& geometry, const FitOptions& options,
                       const std::vector<double>& levels) {
  FitContext context;
  context.stack = &stack;
  context.geometry = &geometry;
  context.options = &options;
  const std::size_t pixel_count = static_cast<std::size_t>(stack.grid.width) * stack.grid.height;
  std::vector<double> positive;
  for (std::size_t k = 0; k < stack.observations.size(); ++k) {
    const Observation& o = stack.observations[k];
    ObservationInfo info;
    info.observation = &o;
    info.light = &stack.lights[o.light];
    info.view = &stack.views[o.view];
    info.level = levels.empty() ? MedianLuminance(o, pixel_count) : levels[k];
    if (info.level > 0.0) positive.push_back(info.level);
    context.observations.push_back(info);
  }
  double typical_level = 1.0;
  if (!positive.empty()) {
    std::nth_element(positive.begin(), positive.begin() + positive.size() / 2, positive.end());
    typical_level = positive[positive.size() / 2];
  }
  for (ObservationInfo& info : context.observations) {
    if (!(info.level > 0.0)) info.level = typical_level;
  }
  // Every observation may be a facet run where the geometry has fine normals.
  context.max_entries = stack.observations.size() * (geometry.fine_normals.empty() ? 1 : kMaxFacets);
  return context;
}

// The value a cluster's pixels take in the maps: its own where it measured the parameter or, in a
// usable cluster, where the clusters hold one value of it (HoldUniformClusterMaps); the U3M default
// elsewhere.
double ValueInMaps(const ClusterModel& model, const ClusterFit& cluster, int parameter) {
  const ParameterEstimate& e = cluster.parameters[parameter];
  const bool held = !model.uniform_reason[parameter].empty() && Usable(model.options, cluster);
  return e.measured || held ? e.value : FitParameterDefault(static_cast<FitParameter>(parameter));
}
}  // namespace

ClusterModel FitClusterModel(const Stack& stack, const SurfaceGeometry& geometry, const FitOptions& options,
                             const ProgressCallback& progress) {
  ValidateInputs(stack, geometry, options);
  ClusterModel model;
  model.options = options;
  const MetricGrid& grid = stack.grid;
  const std::size_t pixel_count = static_cast<std::size_t>(grid.width) * grid.height;
  const FitContext context = MakeContext(stack, geometry, options, {});
  for (const ObservationInfo& info : context.observations) model.observation_levels.push_back(info.level);

  // 1. Gather: features of an evenly strided candidate set of pixels.
  double t = SteadySeconds();
  ReportProgress(progress, "fit: gather", 0.0);
  const std::size_t candidate_count = std::min<std::size_t>(pixel_count, options.clustering.max_samples);
  std::vector<std::size_t> candidates(candidate_count);
  for (std::size_t i = 0; i < candidate_count; ++i) candidates[i] = i * pixel_count / candidate_count;
  std::vector<float> features(candidate_count * kAppearanceFeatureCount);
  std::vector<std::uint8_t> valid(candidate_count, 0);
  ParallelFor(candidate_count, [&](std::size_t begin, std::size_t end) {
    PixelBuffers buffers(context.max_entries);
    for (std::size_t i = begin; i < end; ++i) {
      bool enough = false;
      PixelFeatures(context, candidates[i], buffers, &features[i * kAppearanceFeatureCount], &enough);
      valid[i] = enough ? 1 : 0;
    }
  });
  model.times.gather_s = SteadySeconds() - t;

  // 2. Clustering of the candidates.
  t = SteadySeconds();
  ReportProgress(progress, "fit: clustering", 0.0);
  const Clustering clustering = ClusterPixels(features, kAppearanceFeatureCount, valid, options.clustering);
  model.times.clustering_s = SteadySeconds() - t;
  const int k = clustering.cluster_count;
  if (k == 0) throw std::invalid_argument("FitPrincipled: no pixel has enough usable observations");

  // 3. Cluster fits on evenly spread samples of each cluster's candidates, clusters in parallel.
  t = SteadySeconds();
  std::vector<std::vector<std::size_t>> members(k);
  for (std::size_t i = 0; i < candidate_count; ++i) {
    if (clustering.labels[i] >= 0) members[clustering.labels[i]].push_back(candidates[i]);
  }
  std::vector<ClusterSamples> samples(k);
  model.clusters.resize(k);
  const ParameterMask candidates_all = Candidates(options);
  const ParameterVector defaults = DefaultParameters();
  std::vector<double> observability_s(k, 0.0);
  std::atomic<int> done{0};
  std::mutex progress_mutex;
  ParallelFor(static_cast<std::size_t>(k), [&](std::size_t begin, std::size_t end) {
    std::vector<LocalObservation> buffer(context.max_entries);
    for (std::size_t c = begin; c < end; ++c) {
      const std::vector<std::size_t>& m = members[c];
      const std::size_t take = std::min<std::size_t>(m.size(), options.samples_per_cluster);
      ClusterSamples& s = samples[c];
      s.offsets.push_back(0);
      for (std::size_t j = 0; j < take; ++j) {
        const int count = GatherPixel(context, m[j * m.size() / take], buffer.data(), nullptr);
        if (!EnoughMeasurements(context, buffer.data(), count)) continue;
        s.observations.insert(s.observations.end(), buffer.begin(), buffer.begin() + count);
        s.offsets.push_back(s.observations.size());
        s.luminance_start.push_back(0.2);
      }
      model.clusters[c] = FitCluster(static_cast<int>(c), s, options, candidates_all, defaults, /*search_rotation=*/true,
                                     &observability_s[c]);
      std::size_t saturated = 0, seen = 0;  // over the sampled pixels' observations
      for (std::size_t j = 0; j < take; ++j) {
        const std::size_t index = m[j * m.size() / take];
        for (const Observation& o : stack.observations) {
          ++seen;
          if (!o.flags.empty() && (o.flags[index] & kSaturated) != 0) ++saturated;
        }
      }
      const double saturated_share = seen > 0 ? static_cast<double>(saturated) / static_cast<double>(seen) : 0.0;
      // Normal refinement: the sampled pixels' normals refitted with the full model at the
      // cluster's parameters, then the cluster refitted on them (see RefineNormal); passes until
      // the normals stop moving (mean change below normal_refinement_tolerance_deg).
      NormalRefinementScratch scratch;
      std::vector<Eigen::Vector3d> previous(take, Eigen::Vector3d::Zero());
      for (std::size_t j = 0; j < take; ++j) {
        const Eigen::Vector3d n = GeometryNormal(context, m[j * m.size() / take]);
        if (n.norm() > kMinNormalLength && n.norm() < kMaxNormalLength) previous[j] = n.normalized();
      }
      int passes = 0;
      double change_deg = 0.0;
      for (int pass = 0; pass < options.normal_refinement_max_passes && s.pixels() > 0; ++pass) {
        // The turn found by the first fit holds for the passes (they refine normals, not it).
        const double rotation_deg = model.clusters[c].anisotropy_rotation_deg;
        ParameterVector params;
        ParameterMask free{};
        for (int i = 0; i < kFitParameterCount; ++i) {
          const ParameterEstimate& e = model.clusters[c].parameters[i];
          params[i] = e.measured ? e.value : FitParameterDefault(static_cast<FitParameter>(i));
          free[i] = e.measured;
        }
        ClusterSamples refined;
        refined.rotation_deg = rotation_deg;
        refined.offsets.push_back(0);
        double change_sum = 0.0;
        int changed = 0;
        for (std::size_t j = 0; j < take; ++j) {
          const std::size_t index = m[j * m.size() / take];
          if (!EnoughMeasurements(context, buffer.data(), GatherPixel(context, index, buffer.data(), nullptr))) continue;
          const PixelCostSettings settings =
              CostSettingsFor(options, params, free, Luminance(model.clusters[c].mean_base_color));
          int count = 0;
          const Eigen::Vector3d n = RefineNormal(context, index, params, rotation_deg, settings,
                                                 options.normal_iterations, buffer.data(), scratch, &count);
          change_sum += std::atan2(n.cross(previous[j]).norm(), n.dot(previous[j])) * 180.0 / M_PI;
          ++changed;
          previous[j] = n;
          if (!EnoughMeasurements(context, buffer.data(), count)) continue;
          refined.observations.insert(refined.observations.end(), buffer.begin(), buffer.begin() + count);
          refined.offsets.push_back(refined.observations.size());
          refined.luminance_start.push_back(0.2);
        }
        s = std::move(refined);
        double pass_observability_s = 0.0;
        model.clusters[c] = FitCluster(static_cast<int>(c), s, options, candidates_all, defaults,
                                       /*search_rotation=*/false, &pass_observability_s);
        observability_s[c] += pass_observability_s;
        ++passes;
        change_deg = changed > 0 ? change_sum / changed : 0.0;
        if (change_deg < options.normal_refinement_tolerance_deg) break;
      }
      model.clusters[c].normal_passes = passes;
      model.clusters[c].normal_change_deg = change_deg;
      model.clusters[c].saturated_share = saturated_share;
      std::lock_guard lock(progress_mutex);
      ReportProgress(progress, "fit: clusters", static_cast<double>(++done) / k);
    }
  });
  // The maps as a whole (docs/fitting.md): each cluster keeps a parameter up to twice max_std at its
  // final solution, but a map must be known to max_std (the woven pure velvet seen from above
  // reported sheen 0 for 1, pooled 0.055-0.071). The clusters that measured a parameter so left
  // out are fitted again with it at its default, so that what they keep explains the data with the
  // value the maps hold: the values fitted beside the dropped one paired them with a lobe that is
  // not written (denim, near rig, best: roughness error 0.177 -> 0.081, re-render 44.5 -> 18.6 %).
  std::vector<std::size_t> cluster_weight(k);
  for (int c = 0; c < k; ++c) cluster_weight[c] = members[c].size();
  // Cluster c fitted again on its samples with the parameters in `fixed` at their `values`.
  auto refit = [&](int c, const ParameterMask& fixed, const ParameterVector& values) {
    FitOptions refit_options = options;
    refit_options.metallic_if_demanded = options.metallic_if_demanded && !fixed[kMetallic];
    ParameterMask candidates = candidates_all;
    for (int i = 0; i < kFitParameterCount; ++i) candidates[i] = candidates[i] && !fixed[i];
    // What the cluster fit learnt before the refit and FitCluster does not: its normal passes and
    // the saturation of its samples.
    ClusterFit& cluster = model.clusters[c];
    const int passes = cluster.normal_passes;
    const double change_deg = cluster.normal_change_deg, saturated_share = cluster.saturated_share;
    cluster = FitCluster(c, samples[c], refit_options, candidates, values, /*search_rotation=*/false, &observability_s[c]);
    cluster.normal_passes = passes;
    cluster.normal_change_deg = change_deg;
    cluster.saturated_share = saturated_share;
  };
  const ParameterMask left_out = LeaveOutMapsNotKnownAsAWhole(
      options, cluster_weight, &model.clusters, [&](int c, const ParameterMask& fixed) { refit(c, fixed, defaults); });
  // A map uniform within noise is written as one constant (docs/fitting.md): the clusters are
  // fitted with it, as above, for the same reason (moving their values after the fit broke the
  // joint fit: denim, near rig, balanced: re-render 18.6 -> 38.5 %).
  model.uniform_reason = HoldUniformClusterMaps(
      options, cluster_weight, &model.clusters, [&](int c, const ParameterMask& held, const ParameterVector& values) {
        ParameterMask fixed = held;
        for (int i = 0; i < kFitParameterCount; ++i) fixed[i] = fixed[i] || left_out[i];
        refit(c, fixed, values);
      });
  model.times.cluster_fit_s = SteadySeconds() - t;
  for (double s : observability_s) model.times.observability_s += s;
  for (const ClusterFit& c : model.clusters) {
    if (!c.converged) {
      model.convergence.all_converged = false;
      ++model.convergence.clusters_failed;
      model.convergence.messages.push_back("cluster " + std::to_string(c.id) + ": " + c.message);
      LogWarning() << "fitting: cluster " << c.id << " did not converge: " << c.message;
    }
    if (c.rms_relative_residual > MismatchThreshold(options)) {
      char buffer[200];
      std::snprintf(buffer, sizeof buffer,
                    "cluster %d: likely model mismatch, relative RMS residual %.3g > %.3g (the Principled model does "
                    "not explain these pixels; expect biased parameters)",
                    c.id, c.rms_relative_residual, MismatchThreshold(options));
      model.convergence.messages.push_back(buffer);
      LogWarning() << "fitting: " << buffer;
    }
  }

  // A cluster the model explains grossly badly (cast shadows under grazing lights, pile or weave
  // geometry below the pixel) measures nothing: its parameters would be reported with errors far
  // above their posterior std (grazing rig: roughness 0.06 for 0.6 at a relative RMS residual of
  // 0.18-0.89). Left out with the reason; the cluster's pixels keep the defaults.
  for (ClusterFit& c : model.clusters) {
    if (Usable(options, c)) continue;
    char buffer[220];
    std::snprintf(buffer, sizeof buffer,
                  "the Principled model does not explain this cluster's data (relative RMS residual %.3g > %.3g): "
                  "its value would be biased",
                  c.rms_relative_residual, options.unusable_relative_rms);
    for (ParameterEstimate& e : c.parameters) {
      if (!e.measured) continue;
      e.measured = false;
      e.std_dev = std::numeric_limits<double>::infinity();
      e.reason = buffer;
    }
  }

  // Hidden lobe (docs/fitting.md, LeaveOutHiddenLobeRoughness): only a capture with saturated
  // highlights can measure a lobe at the lower bound.
  const bool capture_saturated = std::any_of(stack.observations.begin(), stack.observations.end(), [](const Observation& o) {
    return std::any_of(o.flags.begin(), o.flags.end(), [](std::uint8_t f) { return (f & kSaturated) != 0; });
  });
  for (int id : LeaveOutHiddenLobeRoughness(capture_saturated, &model.clusters)) {
    LogWarning() << "fitting: cluster " << id << ": roughness "
                 << model.clusters[id].parameters[kRoughness].reason;
  }

  // Reliability of what the clusters measured (FitOptions, "Reliability"): evidence that the value
  // may be off by more than its posterior std, which assumes the model fits and the data cover it.
  // And how far each cluster's pixels spread beyond their noise: the per-pixel step's prior.
  ParallelFor(static_cast<std::size_t>(k), [&](std::size_t begin, std::size_t end) {
    for (std::size_t c = begin; c < end; ++c) {
      ClusterFit& f = model.clusters[c];
      ParameterVector params;
      ParameterMask measured{};
      for (int i = 0; i < kFitParameterCount; ++i) {
        const ParameterEstimate& e = f.parameters[i];
        params[i] = ValueInMaps(model, f, i);
        measured[i] = e.measured;
      }
      f.highlight_share = HighlightShare(samples[c], params, measured, options);
      // A metal's specular lobe does not depend on `specular`: the highlight test does not apply.
      const bool metal = measured[kMetallic] && params[kMetallic] > 0.0;
      char misfit[240], no_highlight[300];
      std::snprintf(misfit, sizeof misfit,
                    "the model explains this cluster's data only to a relative RMS residual of %.3g (> %.3g): the value "
                    "is likely biased by more than its posterior std",
                    f.rms_relative_residual, MismatchThreshold(options));
      std::snprintf(no_highlight, sizeof no_highlight,
                    "no usable highlight: %.0f %% of the cluster's samples (< %.0f %%) have an observation in which the "
                    "fitted specular lobe carries %.1f %% of the signal, and %.0f %% of their observations are saturated; "
                    "the value is inferred from the highlights' absence (they fall between the lights or clip)",
                    100.0 * f.highlight_share, 100.0 * options.min_highlight_share, 100.0 * options.highlight_lobe_fraction,
                    100.0 * f.saturated_share);
      for (int i = 0; i < kFitParameterCount; ++i) {
        ParameterEstimate& e = f.parameters[i];
        if (!e.measured) continue;
        if (f.rms_relative_residual > MismatchThreshold(options)) {
          e.reliable = false;
          e.unreliable_reason = misfit;
        } else if ((i == kRoughness || i == kSpecular) && !metal && f.highlight_share < options.min_highlight_share) {
          e.reliable = false;
          e.unreliable_reason = no_highlight;
        }
      }
      f.pixel_prior_std = ClusterPixelPriorStd(samples[c], params, measured, StartLuminance(f), options);
    }
  });

  model.clustering = clustering;
  // Which maps exist: a parameter measured in at least one cluster (elsewhere it holds its default).
  for (int i = 0; i < kFitParameterCount; ++i) {
    for (const ClusterFit& c : model.clusters) model.measured_any[i] = model.measured_any[i] || c.parameters[i].measured;
  }
  return model;
}

FitResult StartPixelMaps(const ClusterModel& model, const MetricGrid& grid) {
  FitResult result;
  result.options = model.options;
  result.clusters = model.clusters;
  result.convergence = model.convergence;
  result.times = model.times;
  result.base_color = Image(grid.width, grid.height, 3, 0.0f, grid.pitch_mm);
  result.cluster_id = Image(grid.width, grid.height, 1, -1.0f, grid.pitch_mm);
  if (model.options.refine_pixel_normals) result.normals = Image(grid.width, grid.height, 3, 0.0f, grid.pitch_mm);
  for (int i = 0; i < kFitParameterCount; ++i) {
    if (!model.measured_any[i]) continue;  // left out: no image at all (memory at 36 MP)
    result.parameter_maps[i] =
        Image(grid.width, grid.height, 1, static_cast<float>(FitParameterDefault(static_cast<FitParameter>(i))), grid.pitch_mm);
  }
  const bool turned = std::any_of(model.clusters.begin(), model.clusters.end(),
                                  [](const ClusterFit& c) { return c.anisotropy_rotation_deg != 0.0; });
  if (turned) result.anisotropy_rotation_deg = Image(grid.width, grid.height, 1, 0.0f, grid.pitch_mm);
  return result;
}

void FitPixelRows(const ClusterModel& model, const Stack& band, const SurfaceGeometry& geometry, int row0,
                  FitResult* out, PixelTally* tally, const ProgressCallback& progress) {
  const FitOptions& options = model.options;
  ValidateInputs(band, geometry, options);
  FitResult& result = *out;
  const MetricGrid& grid = band.grid;
  if (grid.width != result.base_color.width() || row0 < 0 || row0 + grid.height > result.base_color.height()) {
    throw std::invalid_argument("FitPixelRows: the band does not lie inside the result's grid");
  }
  if (band.observations.size() != model.observation_levels.size()) {
    throw std::invalid_argument("FitPixelRows: the band's observations are not the model's");
  }
  const double t = SteadySeconds();
  const FitContext context = MakeContext(band, geometry, options, model.observation_levels);
  const Clustering& clustering = model.clustering;
  // Pixels with their own turns make the rotation a map even where every cluster is unturned.
  if (!geometry.fibre_turn_deg.empty() && result.anisotropy_rotation_deg.empty()) {
    result.anisotropy_rotation_deg = Image(result.base_color.width(), result.base_color.height(), 1, 0.0f,
                                           result.base_color.pitch_mm());
  }
  const int k = static_cast<int>(model.clusters.size());
  const auto& measured_any = model.measured_any;
  std::vector<ParameterVector> cluster_params(k);
  std::vector<ParameterMask> cluster_measured(k);
  std::vector<double> cluster_luminance(k);
  for (int c = 0; c < k; ++c) {
    for (int i = 0; i < kFitParameterCount; ++i) {
      const ParameterEstimate& e = model.clusters[c].parameters[i];
      cluster_params[c][i] = ValueInMaps(model, model.clusters[c], i);
      cluster_measured[c][i] = e.measured;
    }
    cluster_luminance[c] = StartLuminance(model.clusters[c]);
  }
  if (tally->cluster_pixels.size() != static_cast<std::size_t>(k)) tally->cluster_pixels.assign(k, 0);

  // 5. Per pixel: label, closed-form base colour, refinement where the data supports it.
  ReportProgress(progress, "fit: pixels", 0.0);
  std::atomic<std::int64_t> fitted{0}, refined{0};
  std::vector<std::int64_t>& cluster_pixels = tally->cluster_pixels;
  std::mutex count_mutex;
  std::size_t rows_done = 0;          // under count_mutex
  ParameterVector variance_delta{};  // under count_mutex: sum of (pixel variance - cluster variance)
  const double gloss_threshold = -std::log(1.0 - options.pixel_min_specular_fraction);
  ParallelFor(static_cast<std::size_t>(grid.height), [&](std::size_t row_begin, std::size_t row_end) {
    PixelBuffers buffers(context.max_entries);
    std::vector<double> r0, r1, jac;
    r0.reserve(3 * context.max_entries);
    r1.reserve(3 * context.max_entries);
    jac.reserve(3 * context.max_entries * kMaxPixelParameters);
    std::vector<std::int64_t> local_pixels(k, 0);
    std::int64_t local_fitted = 0, local_refined = 0;
    ParameterVector local_variance_delta{};
    float feature[kAppearanceFeatureCount];
    NormalRefinementScratch normal_scratch;  // RefineNormal's buffers, grown once per chunk
    const bool refine_normals = !result.normals.empty();
    for (std::size_t row = row_begin; row < row_end; ++row) {
      for (int col = 0; col < grid.width; ++col) {
        const std::size_t index = row * grid.width + col;
        bool enough = false;
        int count = PixelFeatures(context, index, buffers, feature, &enough);
        if (refine_normals) {  // the reconstruction's normal unless refined below
          const Eigen::Vector3d n = GeometryNormal(context, index);
          for (int ch = 0; ch < 3; ++ch) result.normals.at(ch, row0 + row, col) = static_cast<float>(n(ch));
        }
        if (!enough) {
          if (!geometry.albedo.empty()) {
            for (int ch = 0; ch < 3; ++ch) {
              result.base_color.at(ch, row0 + row, col) = std::clamp(geometry.albedo.at(ch, row, col), 0.0f, 1.0f);
            }
          }
          continue;
        }
        const int c = NearestCluster(clustering, feature, kAppearanceFeatureCount, options.clustering);
        ++local_pixels[c];
        ++local_fitted;
        const double rotation_deg = model.clusters[c].anisotropy_rotation_deg;
        if (!result.anisotropy_rotation_deg.empty()) {
          result.anisotropy_rotation_deg.at(0, row0 + row, col) =
              static_cast<float>(WrapHalfTurnDeg(rotation_deg + PixelTurn(context, index)));
        }
        if (!refine_normals && rotation_deg != 0.0) {  // the cluster's turned tangent, same observations
          count = GatherPixelWithNormal(context, index, GeometryNormal(context, index), rotation_deg,
                                        buffers.observations.data(), nullptr);
        }
        // The cost at the cluster's parameters: the normal's refinements and, where the pixel keeps
        // them, its colour solve.
        const PixelCostSettings settings = CostSettingsFor(options, cluster_params[c], cluster_measured[c], cluster_luminance[c]);
        if (refine_normals) {
          // The pixel's normal with the full model at its cluster's parameters (as the cluster
          // samples' in FitClusterModel), then its colour and own parameters on that normal.
          // It leaves the pixel's observations in the refined normal's frame in the buffer.
          const Eigen::Vector3d n = RefineNormal(context, index, cluster_params[c], rotation_deg, settings,
                                                 options.pixel_normal_iterations, buffers.observations.data(),
                                                 normal_scratch, &count);
          for (int ch = 0; ch < 3; ++ch) result.normals.at(ch, row0 + row, col) = static_cast<float>(n(ch));
        }
        ParameterVector params = cluster_params[c];
        Eigen::Vector3d color;
        if (options.mode == FitMode::kPerPixel && feature[kAppearanceFeatureCount - 1] > gloss_threshold &&
            count >= 2 * kMaxPixelParameters) {
          ParameterVector kept_sd;
          kept_sd.fill(-1.0);
          bool joint = false;
          if (refine_normals && options.refine_normal_with_lobe) {
            const Eigen::Vector3d start(result.normals.at(0, row0 + row, col), result.normals.at(1, row0 + row, col),
                                        result.normals.at(2, row0 + row, col));
            const Eigen::Vector3d n = RefineNormalAndLobe(
                context, index, start, cluster_measured[c], model.clusters[c].pixel_prior_std, cluster_params[c],
                rotation_deg, settings, buffers.observations.data(), normal_scratch, &count, &params, &color, &kept_sd, &joint);
            for (int ch = 0; ch < 3; ++ch) result.normals.at(ch, row0 + row, col) = static_cast<float>(n(ch));
          }
          const std::span<const LocalObservation> obs(buffers.observations.data(), count);
          if (joint || RefinePixel(obs, options, cluster_measured[c], model.clusters[c].pixel_prior_std, cluster_luminance[c],
                                   cluster_params[c], params, r0, r1, jac, &color, &kept_sd) > 0) {
            ++local_refined;
            // The pixel's own uncertainty replaces the cluster's in the pooled uncertainty.
            for (int i = 0; i < kFitParameterCount; ++i) {
              if (kept_sd[i] < 0.0) continue;
              const double cluster_sd = result.clusters[c].parameters[i].std_dev;
              local_variance_delta[i] += kept_sd[i] * kept_sd[i] - (std::isfinite(cluster_sd) ? cluster_sd * cluster_sd : 0.0);
            }
          }
        } else {
          const std::span<const LocalObservation> obs(buffers.observations.data(), count);
          color = SolveBaseColor(params, obs, settings);  // params are the cluster's here
        }
        for (int ch = 0; ch < 3; ++ch) {
          const double v = std::isfinite(color(ch)) ? std::clamp(color(ch), 0.0, 1.0) : 0.0;
          result.base_color.at(ch, row0 + row, col) = static_cast<float>(v);
        }
        for (int i = 0; i < kFitParameterCount; ++i) {
          if (measured_any[i]) result.parameter_maps[i].at(0, row0 + row, col) = static_cast<float>(params[i]);
        }
        result.cluster_id.at(0, row0 + row, col) = static_cast<float>(c);
      }
    }
    fitted += local_fitted;
    refined += local_refined;
    std::lock_guard lock(count_mutex);
    for (int c = 0; c < k; ++c) cluster_pixels[c] += local_pixels[c];
    for (int i = 0; i < kFitParameterCount; ++i) variance_delta[i] += local_variance_delta[i];
    rows_done += row_end - row_begin;
    ReportProgress(progress, "fit: pixels", static_cast<double>(rows_done) / grid.height);
  });
  tally->fitted += fitted;
  tally->refined += refined;
  for (int i = 0; i < kFitParameterCount; ++i) tally->variance_delta[i] += variance_delta[i];
  tally->seconds += SteadySeconds() - t;
}

// The anisotropy rotation's report, once the anisotropic map is decided: measured where that map
// is (a turn means nothing without a stretch) and the search ran; constant when every cluster that
// measures anisotropic has the same turn (the image is then dropped), else a texture.
void FinishRotationMap(const FitOptions& options, FitResult* out) {
  FitResult& result = *out;
  MapReport& report = result.rotation_report;
  report = MapReport();
  const MapReport& stretch = result.report(FitParameter::kAnisotropic);
  if (!stretch.measured || !options.fit_anisotropy_rotation) {
    report.reason = !options.fit_anisotropy_rotation ? "held at its U3M default by the fit options"
                                                     : "not measured: anisotropic is not measured";
    result.anisotropy_rotation_deg = Image();
    return;
  }
  report.measured = true;
  report.reliable = stretch.reliable;
  report.unreliable_reason = stretch.unreliable_reason;
  const ClusterFit* largest = nullptr;
  bool one_turn = true;
  for (const ClusterFit& c : result.clusters) {
    if (!c.parameters[kAnisotropic].measured || c.pixel_count == 0) continue;
    if (largest != nullptr && c.anisotropy_rotation_deg != largest->anisotropy_rotation_deg) one_turn = false;
    if (largest == nullptr || c.pixel_count > largest->pixel_count) largest = &c;
  }
  // Pixels turned on their own (SurfaceGeometry::fibre_turn_deg) make it a texture.
  if (one_turn && largest != nullptr && !result.anisotropy_rotation_deg.empty()) {
    const auto turns = result.anisotropy_rotation_deg.plane(0);
    const auto ids = result.cluster_id.plane(0);
    for (std::size_t j = 0; j < turns.size() && one_turn; ++j) {
      if (ids[j] >= 0.0f && turns[j] != static_cast<float>(largest->anisotropy_rotation_deg)) one_turn = false;
    }
  }
  if (one_turn || result.anisotropy_rotation_deg.empty()) {
    report.value = largest != nullptr ? largest->anisotropy_rotation_deg : 0.0;
    report.constant = true;
    report.reason = "one turn in every cluster that measures anisotropic";
    result.anisotropy_rotation_deg = Image();
    return;
  }
  double sum = 0.0, sum2 = 0.0;
  std::int64_t n = 0;
  const auto plane = result.anisotropy_rotation_deg.plane(0);
  const auto ids = result.cluster_id.plane(0);
  for (std::size_t j = 0; j < plane.size(); ++j) {
    if (ids[j] < 0.0f) continue;
    sum += plane[j];
    sum2 += static_cast<double>(plane[j]) * plane[j];
    ++n;
  }
  // As for the other maps, a texture's value is its pixel mean (what the U3M constant holds).
  report.value = n > 0 ? sum / static_cast<double>(n) : 0.0;
  report.spread = n > 0 ? std::sqrt(std::max(0.0, sum2 / static_cast<double>(n) - report.value * report.value)) : 0.0;
}

void FinishPixelMaps(const ClusterModel& model, const PixelTally& tally, FitResult* out) {
  FitResult& result = *out;
  const FitOptions& options = model.options;
  const int k = static_cast<int>(model.clusters.size());
  const auto& measured_any = model.measured_any;
  const auto& variance_delta = tally.variance_delta;
  const std::size_t pixel_count = result.base_color.pixel_count();
  for (int c = 0; c < k; ++c) {
    result.clusters[c].pixel_count = c < static_cast<int>(tally.cluster_pixels.size()) ? tally.cluster_pixels[c] : 0;
  }
  result.convergence.pixels_fitted = tally.fitted;
  result.convergence.pixels_refined = tally.refined;
  result.times.per_pixel_s = tally.seconds;

  // Map decisions: left out, constant, or texture.
  for (int i = 0; i < kFitParameterCount; ++i) {
    MapReport& report = result.maps[i];
    const FitParameter p = static_cast<FitParameter>(i);
    if (!measured_any[i]) {
      report.measured = false;
      report.value = FitParameterDefault(p);
      // The reason of the largest cluster speaks for the capture.
      int largest = 0;
      for (int c = 1; c < k; ++c) {
        if (result.clusters[c].pixel_count > result.clusters[largest].pixel_count) largest = c;
      }
      report.reason = "not measured: " + result.clusters[largest].parameters[i].reason;
      continue;
    }
    report.measured = true;
    double sum = 0.0, sum2 = 0.0, pooled = 0.0;
    std::int64_t n = 0, n_pooled = 0;
    const auto plane = result.parameter_maps[i].plane(0);
    const auto ids = result.cluster_id.plane(0);
    for (std::size_t j = 0; j < pixel_count; ++j) {
      if (ids[j] < 0.0f) continue;
      sum += plane[j];
      sum2 += static_cast<double>(plane[j]) * plane[j];
      ++n;
    }
    for (int c = 0; c < k; ++c) {
      const ParameterEstimate& e = result.clusters[c].parameters[i];
      if (e.measured && std::isfinite(e.std_dev)) {
        pooled += e.std_dev * e.std_dev * result.clusters[c].pixel_count;
        n_pooled += result.clusters[c].pixel_count;
      }
    }
    const double mean = n > 0 ? sum / n : FitParameterDefault(p);
    report.value = mean;
    report.spread = n > 0 ? std::sqrt(std::max(0.0, sum2 / n - mean * mean)) : 0.0;
    // Reliable unless the clusters that flag it hold more than unreliable_pixel_share of its pixels.
    std::int64_t flagged_pixels = 0, measuring_pixels = 0;
    int worst_flagged = -1;
    for (int c = 0; c < k; ++c) {
      const ParameterEstimate& e = result.clusters[c].parameters[i];
      if (!e.measured) continue;
      measuring_pixels += result.clusters[c].pixel_count;
      if (e.reliable) continue;
      flagged_pixels += result.clusters[c].pixel_count;
      if (worst_flagged < 0 || result.clusters[c].pixel_count > result.clusters[worst_flagged].pixel_count) worst_flagged = c;
    }
    if (measuring_pixels > 0 &&
        static_cast<double>(flagged_pixels) > options.unreliable_pixel_share * static_cast<double>(measuring_pixels)) {
      char buffer[120];
      std::snprintf(buffer, sizeof buffer, "unreliable in clusters holding %.0f %% of its pixels (largest, cluster %d: ",
                    100.0 * static_cast<double>(flagged_pixels) / static_cast<double>(measuring_pixels), worst_flagged);
      report.reliable = false;
      report.unreliable_reason = buffer + result.clusters[worst_flagged].parameters[i].unreliable_reason + ")";
    } else if (n > 0 && static_cast<double>(measuring_pixels) <
                            (1.0 - options.unreliable_pixel_share) * static_cast<double>(n)) {
      // Measured where it is, but most pixels hold the U3M default: the map as a whole is a guess.
      char buffer[200];
      std::snprintf(buffer, sizeof buffer,
                    "measured only in clusters holding %.0f %% of the fitted pixels; the others hold the U3M default "
                    "%.3g",
                    100.0 * static_cast<double>(measuring_pixels) / static_cast<double>(n), FitParameterDefault(p));
      report.reliable = false;
      report.unreliable_reason = buffer;
    }
    // Pooled uncertainty of a pixel's value: the cluster's, or the pixel's own where refined.
    const double pooled_std = n_pooled > 0 ? std::sqrt(std::max(0.0, pooled + variance_delta[i]) / n_pooled) : 0.0;
    // A map of cluster values had its verdict before the per-pixel step (HoldUniformClusterMaps),
    // and its clusters were fitted to it. One that verdict kept as a texture stays one: judged on
    // the pixels it could be filled with its mean after all, replacing values fitted jointly with
    // the others (the flip of plain at 3x, specular 0.024 / 0.073). One it held is still judged
    // here: the pixels of clusters the model does not explain hold the default, not the constant.
    const bool judged_here = RefinedPerPixel(options, p) || !model.uniform_reason[i].empty();
    if (judged_here && IsUniformWithinNoise(report.spread, pooled_std, options.observability)) {
      report.constant = true;
      char buffer[160];
      std::snprintf(buffer, sizeof buffer, "uniform within noise (spread %.3g, pooled uncertainty %.3g)", report.spread,
                    pooled_std);
      report.reason = model.uniform_reason[i].empty() ? buffer : model.uniform_reason[i];
      auto out = result.parameter_maps[i].plane(0);
      for (std::size_t j = 0; j < pixel_count; ++j) out[j] = static_cast<float>(mean);
    }
  }
  FinishRotationMap(options, &result);
}

FitResult FitPrincipled(const Stack& stack, const SurfaceGeometry& geometry, const FitOptions& options,
                        const ProgressCallback& progress) {
  ClusterModel model;
  return FitPrincipled(stack, geometry, options, progress, &model);
}

FitResult FitPrincipled(const Stack& stack, const SurfaceGeometry& geometry, const FitOptions& options,
                        const ProgressCallback& progress, ClusterModel* model_out) {
  const double t_start = SteadySeconds();
  ClusterModel& model = *model_out;
  model = FitClusterModel(stack, geometry, options, progress);
  FitResult result = StartPixelMaps(model, stack.grid);
  PixelTally tally;
  FitPixelRows(model, stack, geometry, 0, &result, &tally, progress);
  FinishPixelMaps(model, tally, &result);
  result.times.total_s = SteadySeconds() - t_start;
  LogInfo() << "fitting: " << result.clusters.size() << " clusters, " << result.convergence.pixels_fitted << " pixels ("
            << result.convergence.pixels_refined << " refined) in " << result.times.total_s << " s";
  return result;
}

Image RenderFitted(const FitResult& result, const Stack& stack, const SurfaceGeometry& geometry,
                   const Observation& observation) {
  const MetricGrid& grid = stack.grid;
  if (result.base_color.width() != grid.width || result.base_color.height() != grid.height) {
    throw std::invalid_argument("RenderFitted: result and stack grids differ");
  }
  if (observation.light < 0 || observation.light >= static_cast<int>(stack.lights.size()) || observation.view < 0 ||
      observation.view >= static_cast<int>(stack.views.size())) {
    throw std::invalid_argument("RenderFitted: observation light or view out of range");
  }
  if (const std::string problem = FineNormalsProblem(geometry, grid); !problem.empty()) {
    throw std::invalid_argument("RenderFitted: " + problem);
  }
  const bool facets_given = !geometry.fine_normals.empty();
  Image out(grid.width, grid.height, 3, 0.0f, grid.pitch_mm);
  const LightModel& light = stack.lights[observation.light];
  const ViewGeometry& view = stack.views[observation.view];
  ParallelFor(static_cast<std::size_t>(grid.height), [&](std::size_t row_begin, std::size_t row_end) {
    for (std::size_t row = row_begin; row < row_end; ++row) {
      for (int col = 0; col < grid.width; ++col) {
        if (result.cluster_id.at(0, row, col) < 0.0f) continue;
        Eigen::Vector3d n(geometry.normals.at(0, row, col), geometry.normals.at(1, row, col),
                          geometry.normals.at(2, row, col));
        n.normalize();
        const double rotation_deg =
            result.anisotropy_rotation_deg.empty() ? result.rotation_report.value : result.anisotropy_rotation_deg.at(0, row, col);
        const ShadingFrame frame = MakeShadingFrame(n, rotation_deg);
        const double h = geometry.height_mm.empty() ? 0.0 : geometry.height_mm.at(0, row, col);
        const Eigen::Vector3d point = grid.PixelCentreInWorld(col, static_cast<int>(row), h);
        const Eigen::Vector3d lw = light.DirectionFrom(point);
        const Eigen::Vector3d vw = (view.centre_in_world_mm - point).normalized();
        const double e =
            observation.irradiance.empty() ? light.RelativeIrradianceAt(point) : observation.irradiance.at(0, row, col);
        ParameterVector params;
        for (int i = 0; i < kFitParameterCount; ++i) {
          params[i] = result.parameter_maps[i].empty() ? result.maps[i].value : result.parameter_maps[i].at(0, row, col);
        }
        const Eigen::Vector3d c(result.base_color.at(0, row, col), result.base_color.at(1, row, col),
                                result.base_color.at(2, row, col));
        Eigen::Vector3d rgb = Eigen::Vector3d::Zero();
        FacetSet facets;
        const int facet_count =
            facets_given ? ViewFacets(geometry.fine_normals, geometry.fine_factor, col, static_cast<int>(row), vw, &facets) : 0;
        for (int f = 0; f < facet_count; ++f) {  // as the fit modelled this view (WorldEntriesAt)
          const Eigen::Quaterniond back = TurnIntoFacet(n, facets[f]);
          rgb += facets[f].weight * RenderLocal(params, c, frame.ToLocal(back * lw), frame.ToLocal(back * vw), e);
        }
        if (facet_count == 0) rgb = RenderLocal(params, c, frame.ToLocal(lw), frame.ToLocal(vw), e);
        for (int ch = 0; ch < 3; ++ch) out.at(ch, row, col) = static_cast<float>(rgb(ch));
      }
    }
  });
  return out;
}

}  // namespace u3mscan::fitting
