#include "capture/light_joint_fit.h"

#include <ceres/ceres.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <sstream>

namespace u3mscan {
namespace {

// The highlights' own scatter rescales their a priori sigma only with this many spare equations,
// and by at most this factor (a chance small scatter must not make the fit claim any precision).
constexpr int kMinDofForSigmaScale = 10;
constexpr double kMinSigmaScale = 0.02;

// One highlight: the ray from the camera centre O along d (through the highlight pixel, fixed by
// the image) meets the sphere of centre (x, y, z) at P; the ray reflected there must point at the
// light. Residual: the sine of the angle between them (as a 3-vector r x u), over the ray's
// angular sigma.
struct HighlightResidual {
  Eigen::Vector3d origin, dir;
  double centre_z, radius, inverse_sigma;
  bool directional;

  template <typename T>
  bool operator()(const T* centre_xy, const T* light, T* residual) const {
    using V = Eigen::Matrix<T, 3, 1>;
    const V c(centre_xy[0], centre_xy[1], T(centre_z));
    const V o = origin.cast<T>(), d = dir.cast<T>();
    const V oc = o - c;
    const T b = oc.dot(d);
    T disc = b * b - (oc.squaredNorm() - T(radius * radius));
    if (disc < T(0)) disc = T(0);  // the ray grazes the sphere: its tangent point
    const V p = o + (-b - sqrt(disc + T(1e-18))) * d;
    const V n = (p - c) / T(radius);
    const V v = -d;
    const V r = T(2) * n.dot(v) * n - v;
    const V l(light[0], light[1], light[2]);
    const V u = directional ? V(l / l.norm()) : V((l - p) / (l - p).norm());
    const V e = r.cross(u) * T(inverse_sigma);
    for (int k = 0; k < 3; ++k) residual[k] = e[k];
    return true;
  }
};

struct PriorResidual {  // (value - target) / sigma, N components
  Eigen::Vector3d target;
  double inverse_sigma;
  template <typename T>
  bool operator()(const T* value, T* residual) const {
    for (int k = 0; k < 3; ++k) residual[k] = (value[k] - T(target[k])) * T(inverse_sigma);
    return true;
  }
};
struct CentrePrior {
  Eigen::Vector2d target;
  double inverse_sigma;
  template <typename T>
  bool operator()(const T* value, T* residual) const {
    for (int k = 0; k < 2; ++k) residual[k] = (value[k] - T(target[k])) * T(inverse_sigma);
    return true;
  }
};

// The observation seen again with the sphere centred at `centre`: new hit point, normal, ray.
SphereObservation Recentred(SphereObservation o, const Eigen::Vector3d& centre) {
  const Eigen::Vector3d dir = (o.highlight_point_in_world_mm - o.camera_centre_in_world_mm).normalized();
  const Eigen::Vector3d oc = o.camera_centre_in_world_mm - centre;
  const double b = oc.dot(dir);
  const double disc = std::max(0.0, b * b - (oc.squaredNorm() - o.radius_mm * o.radius_mm));
  const Eigen::Vector3d hit = o.camera_centre_in_world_mm + (-b - std::sqrt(disc)) * dir;
  const Eigen::Vector3d normal = (hit - centre).normalized();
  o.centre_in_world_mm = centre;
  o.highlight_point_in_world_mm = hit;
  o.reflected_in_world = (2.0 * normal.dot(-dir) * normal + dir).normalized();
  return o;
}

double RaySigmaRad(const SphereObservation& o, const LightFitOptions& options) {
  const double sigma_px = options.highlight_sigma_px / std::sqrt(std::max(1, o.highlight_area_px));
  return 2.0 * sigma_px / std::max(1.0, o.apparent_radius_px);
}

}  // namespace

JointLightFit FitLightsJointly(const std::vector<JointLightInput>& per_light, const LightFitOptions& options) {
  JointLightFit out;
  // Group the observations into placements: centres within half a radius of a group's first.
  struct Placement {
    std::vector<Eigen::Vector3d> found;
    bool fixed = false;  // a centre from the manifest: not refined
    double xy[2] = {0, 0};
    double z = 0, radius = 0;
    Eigen::Vector2d mean = Eigen::Vector2d::Zero();
    double sigma = 0;  // of the centre prior, mm
  };
  std::vector<Placement> placements;
  std::vector<std::vector<int>> placement_of(per_light.size());
  for (std::size_t l = 0; l < per_light.size(); ++l) {
    for (const auto& o : per_light[l].observations) {
      int found = -1;
      for (std::size_t p = 0; p < placements.size() && found < 0; ++p) {
        if ((placements[p].found.front() - o.centre_in_world_mm).norm() < 0.5 * o.radius_mm &&
            placements[p].fixed == !o.centre_found_in_frame) {
          found = static_cast<int>(p);
        }
      }
      if (found < 0) {
        found = static_cast<int>(placements.size());
        placements.push_back({});
        placements.back().fixed = !o.centre_found_in_frame;
        placements.back().radius = o.radius_mm;
      }
      placements[found].found.push_back(o.centre_in_world_mm);
      placement_of[l].push_back(found);
    }
  }
  out.placements = static_cast<int>(placements.size());
  for (auto& p : placements) {
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (const auto& c : p.found) mean += c;
    mean /= static_cast<double>(p.found.size());
    double scatter = 0.0;
    for (const auto& c : p.found) scatter += (c - mean).head<2>().squaredNorm();
    // Per-frame scatter of the rim fits (1 sigma per axis), at least centre_prior_sigma_of_radius.
    p.sigma = std::max(options.centre_prior_sigma_of_radius * p.radius,
                       std::sqrt(scatter / (2.0 * std::max<std::size_t>(1, p.found.size() - 1))));
    p.mean = mean.head<2>();
    p.xy[0] = mean.x(), p.xy[1] = mean.y(), p.z = mean.z();
  }
  LightFitOptions fit_options = options;  // highlight_sigma_px rescaled from the residuals below
  auto observations_at = [&](std::size_t l) {
    std::vector<SphereObservation> moved;
    for (std::size_t k = 0; k < per_light[l].observations.size(); ++k) {
      const Placement& p = placements[placement_of[l][k]];
      moved.push_back(Recentred(per_light[l].observations[k], Eigen::Vector3d(p.xy[0], p.xy[1], p.z)));
    }
    return moved;
  };
  auto fit_one = [&](std::size_t l) {
    const auto moved = observations_at(l);
    return per_light[l].start.type == LightType::kDirectional ? FitDirectionalLight(moved, per_light[l].start)
                                                               : FitPointLight(moved, per_light[l].start, fit_options);
  };
  bool any_free = false;
  for (const auto& p : placements) any_free = any_free || !p.fixed;
  // One solve: every light started at its own fit on the current centres. Returns the sum of the
  // squared highlight residuals (in sigmas) and their degrees of freedom.
  std::vector<std::array<double, 3>> light_params(per_light.size());
  auto solve = [&](double* chi2, int* dof) {
    ceres::Problem problem;
    int unknowns = 0, equations = 0;
    for (auto& p : placements) {
      problem.AddParameterBlock(p.xy, 2);
      if (p.fixed) {
        problem.SetParameterBlockConstant(p.xy);
      } else {
        unknowns += 2;
        problem.AddResidualBlock(
            new ceres::AutoDiffCostFunction<CentrePrior, 2, 2>(new CentrePrior{p.mean, 1.0 / p.sigma}), nullptr, p.xy);
      }
    }
    std::vector<ceres::ResidualBlockId> highlights;
    for (std::size_t l = 0; l < per_light.size(); ++l) {
      const auto& in = per_light[l];
      if (in.observations.empty()) continue;
      const LightFit first = fit_one(l);
      const bool directional = in.start.type == LightType::kDirectional;
      const Eigen::Vector3d start = directional ? first.model.direction_in_world : first.model.position_in_world_mm;
      light_params[l] = {start.x(), start.y(), start.z()};
      double* x = light_params[l].data();
      problem.AddParameterBlock(x, 3);
      if (directional) problem.SetManifold(x, new ceres::SphereManifold<3>());
      unknowns += directional ? 2 : 3;
      for (std::size_t k = 0; k < in.observations.size(); ++k) {
        const SphereObservation& o = in.observations[k];
        Placement& p = placements[placement_of[l][k]];
        auto* cost = new ceres::AutoDiffCostFunction<HighlightResidual, 3, 2, 3>(new HighlightResidual{
            o.camera_centre_in_world_mm, (o.highlight_point_in_world_mm - o.camera_centre_in_world_mm).normalized(), p.z,
            o.radius_mm, 1.0 / RaySigmaRad(o, fit_options), directional});
        // Huber beyond 3 sigmas: one bad highlight must not drag a centre every light shares.
        highlights.push_back(problem.AddResidualBlock(cost, new ceres::HuberLoss(3.0), p.xy, x));
        equations += 2;  // the angle between two unit vectors: two components
      }
      if (!directional && fit_options.manifest_position_sigma_mm > 0.0) {
        problem.AddResidualBlock(new ceres::AutoDiffCostFunction<PriorResidual, 3, 3>(new PriorResidual{
                                     in.start.position_in_world_mm, 1.0 / fit_options.manifest_position_sigma_mm}),
                                 nullptr, x);
      }
    }
    bool converged = true;
    if (any_free && problem.NumResidualBlocks() > 0) {
      ceres::Solver::Options solver;
      solver.linear_solver_type = ceres::DENSE_SCHUR;
      solver.max_num_iterations = 50;
      solver.num_threads = 1;
      solver.logging_type = ceres::SILENT;
      ceres::Solver::Summary summary;
      ceres::Solve(solver, &problem, &summary);
      converged = summary.termination_type == ceres::CONVERGENCE;
    }
    *chi2 = 0.0;
    for (const auto id : highlights) {
      double r[3];
      problem.EvaluateResidualBlock(id, false, nullptr, r, nullptr);
      *chi2 += r[0] * r[0] + r[1] * r[1] + r[2] * r[2];
    }
    *dof = equations - unknowns;
    return converged;
  };
  double chi2 = 0.0;
  int dof = 0;
  out.converged = solve(&chi2, &dof);
  // A posteriori: where the highlights over-determine the fit, their scatter says how well they
  // are located; LightFitOptions::highlight_sigma_px is a cautious a priori value (the synthetic
  // near rig's highlights sat 25 times closer than it). Rescaled (never up, at most
  // kMinSigmaScale down), and solved again: the manifest prior then weighs what it should.
  if (dof >= kMinDofForSigmaScale && chi2 > 0.0) {
    out.sigma_scale = std::clamp(std::sqrt(chi2 / dof), kMinSigmaScale, 1.0);
    if (out.sigma_scale < 1.0) {
      fit_options.highlight_sigma_px *= out.sigma_scale;
      for (auto& p : placements) p.xy[0] = p.mean.x(), p.xy[1] = p.mean.y();
      out.converged = solve(&chi2, &dof);
    }
  }
  double shift_sq = 0.0;
  int free_count = 0;
  for (const auto& p : placements) {
    if (p.fixed) continue;
    shift_sq += (Eigen::Vector2d(p.xy[0], p.xy[1]) - p.mean).squaredNorm();
    ++free_count;
  }
  out.centre_shift_rms_mm = free_count ? std::sqrt(shift_sq / free_count) : 0.0;
  for (const auto& p : placements) out.placement_centres_mm.emplace_back(p.xy[0], p.xy[1], p.z);
  // Each light's fit on the jointly refined centres: its residual and sigma as the single fits report them.
  for (std::size_t l = 0; l < per_light.size(); ++l) {
    if (per_light[l].observations.empty()) {
      LightFit none;
      none.model = per_light[l].start;
      out.lights.push_back(none);
      continue;
    }
    LightFit fit = fit_one(l);
    std::ostringstream note;
    note << "joint fit over " << placements.size() << " placement(s) and every light's highlights";
    if (out.sigma_scale < 1.0) note << ", highlight sigma x" << out.sigma_scale << " from their scatter";
    if (!fit.note.empty()) note << "; " << fit.note;
    fit.note = note.str();
    out.lights.push_back(std::move(fit));
  }
  return out;
}

}  // namespace u3mscan
