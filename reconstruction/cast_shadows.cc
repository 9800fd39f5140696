#include "reconstruction/cast_shadows.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <atomic>
#include <cstdint>
#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <utility>
#include <vector>

#include "core/elapsed.h"
#include "core/logging.h"
#include "core/parallel.h"
#include "reconstruction/normal_integration.h"

namespace u3mscan::reconstruction {
namespace {

using Eigen::Vector3d;

// The height map as a bilinear surface over continuous pixel coordinates (u = column, v = row,
// pixel centres at integers); coordinates are clamped to the map.
class HeightField {
 public:
  explicit HeightField(const Image& height_mm) : h_(height_mm.plane(0).data()), w_(height_mm.width()), rows_(height_mm.height()) {}
  int width() const { return w_; }
  int height() const { return rows_; }
  float At(double u, double v) const {
    u = std::clamp(u, 0.0, static_cast<double>(w_ - 1));
    v = std::clamp(v, 0.0, static_cast<double>(rows_ - 1));
    const int c0 = std::min(static_cast<int>(u), std::max(0, w_ - 2));
    const int r0 = std::min(static_cast<int>(v), std::max(0, rows_ - 2));
    const int c1 = std::min(c0 + 1, w_ - 1), r1 = std::min(r0 + 1, rows_ - 1);
    const float fu = static_cast<float>(u - c0), fv = static_cast<float>(v - r0);
    const float* a = h_ + static_cast<std::size_t>(r0) * w_;
    const float* b = h_ + static_cast<std::size_t>(r1) * w_;
    const float top = a[c0] + fu * (a[c1] - a[c0]);
    const float bottom = b[c0] + fu * (b[c1] - b[c0]);
    return top + fv * (bottom - top);
  }

 private:
  const float* h_;
  int w_, rows_;
};

}  // namespace

bool CastShadowOptions::Check() const {
  return std::isfinite(step_px) && step_px > 0.0 && step_px <= 4.0 && std::isfinite(bias_px) && bias_px >= 0.0 &&
         std::isfinite(footprint_px) && footprint_px >= 0.0 && footprint_px <= 8.0 && std::isfinite(relief_scale) &&
         relief_scale > 0.0 && relief_scale <= 4.0;
}

CastShadowCounts MarkCastShadows(const Image& height_mm, const MetricGrid& height_grid, Stack* stack,
                                 const CastShadowOptions& options) {
  if (!options.Check()) throw std::invalid_argument("cast shadows: options fail Check()");
  if (height_mm.channels() != 1 || height_mm.width() != height_grid.width || height_mm.height() != height_grid.height ||
      !(height_grid.pitch_mm > 0.0) || height_grid.width < 1 || height_grid.height < 1) {
    throw std::invalid_argument("cast shadows: height_mm must be 1 channel on height_grid");
  }
  const MetricGrid& grid = stack->grid;
  const std::size_t pixels = static_cast<std::size_t>(grid.width) * grid.height;
  // Observations per light; kCastShadow cleared, flags allocated.
  std::vector<std::vector<std::size_t>> by_light(stack->lights.size());
  for (std::size_t k = 0; k < stack->observations.size(); ++k) {
    Observation& o = stack->observations[k];
    if (o.light < 0 || static_cast<std::size_t>(o.light) >= stack->lights.size()) {
      throw std::invalid_argument("cast shadows: observation " + std::to_string(k) + " has no light");
    }
    if (o.flags.empty()) o.flags.assign(pixels, 0);
    if (o.flags.size() != pixels) throw std::invalid_argument("cast shadows: flags must have width*height entries");
    for (auto& f : o.flags) f = static_cast<std::uint8_t>(f & ~kCastShadow);
    by_light[static_cast<std::size_t>(o.light)].push_back(k);
  }

  const HeightField field(height_mm);
  const double scale = options.relief_scale;
  float max_height = -std::numeric_limits<float>::infinity();
  for (float z : height_mm.plane(0)) {
    if (std::isfinite(z)) max_height = std::max(max_height, z);
  }
  const double p = height_grid.pitch_mm;
  const double u_max = height_grid.width - 1, v_max = height_grid.height - 1;
  const double top = scale * max_height;  // mm, on the scaled relief
  // The footprint's sample points, in pixels of the height map's grid from the pixel centre.
  const double half = 0.5 * options.footprint_px;
  std::vector<std::pair<double, double>> offsets = {{0.0, 0.0}};
  if (half > 0.0) offsets.insert(offsets.end(), {{half, 0.0}, {-half, 0.0}, {0.0, half}, {0.0, -half}});
  std::atomic<long long> marked{0};

  // Whether the ray from the surface point over (u, v) (continuous pixel coordinates of the height
  // map, inside it) toward `model` is blocked by the scaled relief.
  auto blocked = [&](const LightModel& model, double u, double v) {
    const double z0 = scale * field.At(u, v);
    if (!std::isfinite(z0)) return false;
    const Vector3d point(height_grid.x0_mm + (u + 0.5) * p, height_grid.y1_mm - (v + 0.5) * p, z0);
    const Vector3d d = model.DirectionFrom(point);
    if (!(d.z() > 0.0)) return true;  // below the sample plane: lights nothing
    const double speed = std::hypot(d.x(), d.y());  // horizontal length per unit ray length
    if (!(speed > 1e-12)) return false;
    const double bias_mm = options.bias_px * p * d.z() / speed;
    if (!(z0 + bias_mm < top)) return false;
    const double du = options.step_px * d.x() / speed, dv = -options.step_px * d.y() / speed;
    const double dz = options.step_px * p * d.z() / speed;
    // A point light ends the ray: no march past its horizontal distance.
    double steps_left = std::numeric_limits<double>::infinity();
    if (model.type == LightType::kPoint) {
      steps_left = std::hypot(model.position_in_world_mm.x() - point.x(), model.position_in_world_mm.y() - point.y()) /
                   (options.step_px * p);
    }
    double z = z0;
    for (double s = 1.0; s <= steps_left; s += 1.0) {
      u += du, v += dv, z += dz;
      if (u < 0.0 || v < 0.0 || u > u_max || v > v_max || z > top) return false;
      if (z < scale * field.At(u, v) - bias_mm) return true;
    }
    return false;
  };

  // Aligned grids (the height map's own grid or a band of it) with a footprint of whole pixels:
  // the footprint's points are the neighbours' centres, so each centre's ray is marched once per
  // light, into `centre_blocked` over the stack's rows and columns widened by the footprint, and
  // looked up, instead of marched again for each of its 4 neighbours. Same marks, up to 5 x
  // fewer marches. Other grids (a sample at pitch k p) march every point.
  const auto whole = [](double x) { return std::abs(x - std::round(x)) < 1e-6; };
  const double first_col = (grid.x0_mm - height_grid.x0_mm) / p, first_row = (height_grid.y1_mm - grid.y1_mm) / p;
  const bool aligned = half > 0.0 && whole(half) && std::abs(grid.pitch_mm - p) <= 1e-9 * p && whole(first_col) &&
                       whole(first_row);
  const int reach = static_cast<int>(std::lround(half));
  const int region_c0 = aligned ? std::max(0, static_cast<int>(std::lround(first_col)) - reach) : 0;
  const int region_r0 = aligned ? std::max(0, static_cast<int>(std::lround(first_row)) - reach) : 0;
  const int region_c1 =
      aligned ? std::min(height_grid.width - 1, static_cast<int>(std::lround(first_col)) + grid.width - 1 + reach) : -1;
  const int region_r1 =
      aligned ? std::min(height_grid.height - 1, static_cast<int>(std::lround(first_row)) + grid.height - 1 + reach) : -1;
  const bool use_region = aligned && region_c1 >= region_c0 && region_r1 >= region_r0;
  const int region_cols = use_region ? region_c1 - region_c0 + 1 : 0;
  std::vector<std::uint8_t> centre_blocked(
      use_region ? static_cast<std::size_t>(region_cols) * static_cast<std::size_t>(region_r1 - region_r0 + 1) : 0);

  for (std::size_t light = 0; light < by_light.size(); ++light) {
    const std::vector<std::size_t>& observations = by_light[light];
    if (observations.empty()) continue;
    const LightModel& model = stack->lights[light];
    if (use_region) {
      ParallelFor(static_cast<std::size_t>(region_r1 - region_r0 + 1), [&](std::size_t begin, std::size_t end) {
        for (std::size_t r = begin; r < end; ++r) {
          for (int c = 0; c < region_cols; ++c) {
            centre_blocked[r * static_cast<std::size_t>(region_cols) + static_cast<std::size_t>(c)] =
                blocked(model, region_c0 + c, region_r0 + static_cast<double>(r)) ? 1 : 0;
          }
        }
      });
    }
    ParallelFor(static_cast<std::size_t>(grid.height), [&](std::size_t begin, std::size_t end) {
      long long chunk_marked = 0;
      for (std::size_t row = begin; row < end; ++row) {
        for (int col = 0; col < grid.width; ++col) {
          const Vector3d centre = grid.PixelCentreInWorld(col, static_cast<int>(row));
          // The pixel centre in the height map's continuous pixel coordinates.
          double u = (centre.x() - height_grid.x0_mm) / p - 0.5;
          double v = (height_grid.y1_mm - centre.y()) / p - 0.5;
          constexpr double kInside = 1e-6;  // rounding of the grid's mm coordinates, in pixels
          if (u < -kInside || v < -kInside || u > u_max + kInside || v > v_max + kInside) continue;
          u = std::clamp(u, 0.0, u_max);
          v = std::clamp(v, 0.0, v_max);
          if (!std::isfinite(field.At(u, v))) continue;
          bool shadow = false;
          for (const auto& [du, dv] : offsets) {
            // Footprint points off the map are not looked at (the map's edge has no relief beyond).
            const double us = u + du, vs = v + dv;
            if (us < 0.0 || vs < 0.0 || us > u_max || vs > v_max) continue;
            const bool hit =
                use_region ? centre_blocked[static_cast<std::size_t>(std::lround(vs) - region_r0) * region_cols +
                                            static_cast<std::size_t>(std::lround(us) - region_c0)] != 0
                           : blocked(model, us, vs);
            if (hit) {
              shadow = true;
              break;
            }
          }
          if (!shadow) continue;
          const std::size_t i = row * static_cast<std::size_t>(grid.width) + static_cast<std::size_t>(col);
          for (std::size_t k : observations) stack->observations[k].flags[i] |= kCastShadow;
          chunk_marked += static_cast<long long>(observations.size());
        }
      }
      marked += chunk_marked;
    });
  }
  CastShadowCounts counts;
  counts.marked = marked.load();
  counts.examined = static_cast<long long>(pixels) * static_cast<long long>(stack->observations.size());
  return counts;
}

CastShadowCounts MarkCastShadows(const Image& height_mm, Stack* stack, const CastShadowOptions& options) {
  return MarkCastShadows(height_mm, stack->grid, stack, options);
}

PhotometricStereoResult RunPhotometricStereoMarkingShadows(Stack* stack, const PhotometricStereoOptions& options,
                                                           const CastShadowOptions& shadow_options,
                                                           ShadowMarkingSummary* summary,
                                                           const ProgressCallback& progress) {
  if (!shadow_options.Check()) throw std::invalid_argument("cast shadows: options fail Check()");
  ShadowMarkingSummary local;
  ShadowMarkingSummary& out = summary ? *summary : local;
  out = {};
  const bool point_lights = std::any_of(stack->lights.begin(), stack->lights.end(),
                                        [](const LightModel& l) { return l.type == LightType::kPoint; });
  const bool near = options.refine_height && point_lights;
  IntegrationOptions integration = options.integration;
  integration.pitch_mm = stack->grid.pitch_mm;

  // First solve without marks (a stack marked before, e.g. solved twice, starts clean): the plain
  // near-light model on the anchor plane, or the distant one.
  for (Observation& o : stack->observations) {
    for (auto& f : o.flags) f = static_cast<std::uint8_t>(f & ~kCastShadow);
  }
  PhotometricStereoOptions first = options;
  first.refine_height = false;
  PhotometricStereoResult result = RunPhotometricStereo(*stack, first, progress);
  // The roughness chosen on the first solve, kept for the solves with marks.
  PhotometricStereoOptions again = options;
  if (options.diffuse_model == DiffuseModel::kBurley) {
    if (result.diffuse_roughness >= 0.0) {
      again.diffuse_roughness = result.diffuse_roughness;
    } else {
      again.diffuse_model = DiffuseModel::kLambert;
    }
  }
  const double roughness = result.diffuse_roughness;

  if (!near) {
    const double start = SteadySeconds();
    const Image height = IntegrateNormals(result.normal, result.confidence, integration).height_mm;
    out.counts = MarkCastShadows(height, stack, shadow_options);
    out.mark_seconds += SteadySeconds() - start;
    // Nothing marked (e.g. lights high enough for the relief): the first solve stands.
    if (out.counts.marked == 0) {
      out.solved_again_share = 0.0;
      return result;
    }
    // Distant lights do not depend on the height; near lights without refinement stay on the plane.
    // Only the pixels with a mark (and those solved from their neighbours) can change: the others
    // keep the first solve (31-64 % of the pixels on the 192 px woven captures of
    // docs/reconstruction.md, "Cast shadows").
    const Image kept_height = std::move(result.height_mm);
    const Image& solve_height = kept_height.empty() ? height : kept_height;
    result = point_lights ? SolvePhotometricStereoAt(*stack, again, solve_height)
                          : SolvePhotometricStereoAgain(*stack, again, solve_height, result, kCastShadow);
    result.height_mm = kept_height;
    result.diffuse_roughness = roughness;
    out.solved_again_share =
        1.0 - static_cast<double>(result.kept_pixels) / (static_cast<double>(stack->grid.width) * stack->grid.height);
    return result;
  }

  // Near point lights: RunPhotometricStereo's refinement, marks renewed after each integration
  // (and for the kept round's height when a round is rejected, so the stack's marks are the ones
  // the result was solved with).
  result = RefineNearLightHeights(
      std::move(result), options, stack->grid.pitch_mm,
      [&](const Image& height) { return SolvePhotometricStereoAt(*stack, again, height); },
      [&](const Image& height, bool /*kept_round*/) {
        const double start = SteadySeconds();
        out.counts = MarkCastShadows(height, stack, shadow_options);
        out.mark_seconds += SteadySeconds() - start;
      },
      progress);
  result.diffuse_roughness = roughness;
  ReportProgress(progress, "photometric stereo", 1.0);
  return result;
}

}  // namespace u3mscan::reconstruction
