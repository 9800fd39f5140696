#include "capture/light_from_plane.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <sstream>

namespace u3mscan {
namespace {

struct Sample {
  Eigen::Vector3d x;  // on z = 0, world mm
  double value;       // mean over channels of v_c / intensity_c
  double rho2;        // (distance to the principal point / half-diagonal)^2
};

double Bilinear(const Image& image, int channel, double u, double v) {
  const int u0 = static_cast<int>(std::floor(u)), v0 = static_cast<int>(std::floor(v));
  const double fu = u - u0, fv = v - v0;
  return (1 - fv) * ((1 - fu) * image.at(channel, v0, u0) + fu * image.at(channel, v0, u0 + 1)) +
         fv * ((1 - fu) * image.at(channel, v0 + 1, u0) + fu * image.at(channel, v0 + 1, u0 + 1));
}

// Golden-section minimum of f on [a, b] (f unimodal there).
double GoldenMinimum(const std::function<double(double)>& f, double a, double b, double tolerance) {
  constexpr double kInvPhi = 0.6180339887498949;
  double c = b - kInvPhi * (b - a), d = a + kInvPhi * (b - a);
  double fc = f(c), fd = f(d);
  while (b - a > tolerance) {
    if (fc < fd) {
      b = d, d = c, fd = fc;
      c = b - kInvPhi * (b - a), fc = f(c);
    } else {
      a = c, c = d, fc = fd;
      d = a + kInvPhi * (b - a), fd = f(d);
    }
  }
  return 0.5 * (a + b);
}

// Coarse scan of f over `values`, then a golden refinement between the best one's neighbours.
// *at_edge: the best coarse value was the first or the last.
double ScanThenRefine(const std::function<double(double)>& f, const std::vector<double>& values, double tolerance,
                      bool* at_edge) {
  std::size_t best = 0;
  double best_f = f(values[0]);
  for (std::size_t i = 1; i < values.size(); ++i) {
    const double fi = f(values[i]);
    if (fi < best_f) best_f = fi, best = i;
  }
  if (at_edge) *at_edge = best == 0 || best + 1 == values.size();
  const double a = values[best == 0 ? 0 : best - 1], b = values[std::min(best + 1, values.size() - 1)];
  return GoldenMinimum(f, a, b, tolerance);
}

}  // namespace

PlaneLightFit FitPointLightOnPlane(const Image& flat_rgb, const std::vector<std::uint8_t>& saturated,
                                   const CameraModel& camera, const LightModel& start,
                                   const Eigen::Vector3d& ray_origin_mm, const Eigen::Vector3d& ray_direction,
                                   const std::array<double, 4>& region_mm, const std::string& frame_file,
                                   const PlaneLightFitOptions& options) {
  PlaneLightFit fit;
  fit.model = start;
  fit.model.type = LightType::kPoint;
  const Eigen::Vector3d r = ray_direction.normalized();
  const double t0 = (start.position_in_world_mm - ray_origin_mm).dot(r);
  if (!(t0 > 0.0) || !(r.z() > 0.0)) {
    fit.reason = frame_file + ": the sphere's ray does not point above the target (no distance to search)";
    return fit;
  }

  // The target on a coarse grid of world points, sampled in the frame through the camera's pose.
  const int n = std::max(3, options.samples_per_side);
  const double mx = options.margin_fraction * (region_mm[2] - region_mm[0]);
  const double my = options.margin_fraction * (region_mm[3] - region_mm[1]);
  const double half_diagonal = 0.5 * std::hypot(camera.width, camera.height);
  const int channels = flat_rgb.channels();
  std::vector<Sample> samples;
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      const Eigen::Vector3d x(region_mm[0] + mx + (region_mm[2] - region_mm[0] - 2 * mx) * i / (n - 1),
                              region_mm[1] + my + (region_mm[3] - region_mm[1] - 2 * my) * j / (n - 1), 0.0);
      bool in_front = false;
      const Eigen::Vector2d u = camera.Project(x, &in_front);
      if (!in_front || !(u.x() >= 1.0) || !(u.y() >= 1.0) || !(u.x() <= flat_rgb.width() - 2.0) ||
          !(u.y() <= flat_rgb.height() - 2.0)) {
        continue;
      }
      const int uc = static_cast<int>(u.x()), vc = static_cast<int>(u.y());
      bool clipped = false;
      for (int dv = 0; dv <= 1 && !saturated.empty(); ++dv) {
        for (int du = 0; du <= 1; ++du) {
          clipped = clipped || saturated[static_cast<std::size_t>(vc + dv) * flat_rgb.width() + uc + du] != 0;
        }
      }
      if (clipped) continue;
      double value = 0.0;
      for (int c = 0; c < channels; ++c) {
        value += Bilinear(flat_rgb, c, u.x(), u.y()) / std::max(1e-30, start.intensity_rgb[std::min(c, 2)]);
      }
      value /= channels;
      if (!(value > 0.0) || !std::isfinite(value)) continue;
      const double du = u.x() - camera.intrinsics.cx, dv = u.y() - camera.intrinsics.cy;
      samples.push_back({x, value, (du * du + dv * dv) / (half_diagonal * half_diagonal)});
    }
  }
  fit.samples = static_cast<int>(samples.size());
  if (fit.samples < options.min_samples) {
    std::ostringstream reason;
    reason << frame_file << ": " << fit.samples << " usable points of the white target in view (at least "
           << options.min_samples << " needed: lit, not saturated, inside the frame)";
    fit.reason = reason.str();
    return fit;
  }

  const Eigen::Vector3d target_centre(0.5 * (region_mm[0] + region_mm[2]), 0.5 * (region_mm[1] + region_mm[3]), 0.0);
  fit.exponent_fitted = !start.has_profile;
  // Residual sum of the relative shading fit at distance t and exponent n, with the scale and the
  // vignetting solved in closed form (weighted linear least squares, weights 1 / value).
  Eigen::MatrixXd a(samples.size(), 3);
  const Eigen::VectorXd ones = Eigen::VectorXd::Ones(static_cast<Eigen::Index>(samples.size()));
  Eigen::Vector3d last_solution = Eigen::Vector3d::Zero();
  auto ssr = [&](double t, double exponent) {
    const Eigen::Vector3d p = ray_origin_mm + t * r;
    const Eigen::Vector3d axis = start.has_profile ? start.profile_axis_in_world : (target_centre - p).normalized();
    for (std::size_t k = 0; k < samples.size(); ++k) {
      const Eigen::Vector3d from_light = samples[k].x - p;
      const double d2 = from_light.squaredNorm(), d = std::sqrt(d2);
      const double cos_i = std::max(0.0, p.z() / d);
      const double profile = std::pow(std::max(0.0, axis.dot(from_light) / d), exponent);
      const double g = cos_i * profile / d2 / samples[k].value;
      a(k, 0) = g, a(k, 1) = g * samples[k].rho2, a(k, 2) = g * samples[k].rho2 * samples[k].rho2;
    }
    const Eigen::Matrix3d normal = a.transpose() * a;
    last_solution = normal.ldlt().solve(a.transpose() * ones);
    return (a * last_solution - ones).squaredNorm();
  };
  std::vector<double> exponents;
  for (int k = 0; k <= 40; ++k) exponents.push_back(options.max_profile_exponent * k / 40.0);
  double exponent_at_t = start.profile_exponent;
  bool exponent_at_edge = false;
  // Every unknown but t minimised out.
  auto profiled = [&](double t) {
    if (!fit.exponent_fitted) return ssr(t, start.has_profile ? start.profile_exponent : 0.0);
    bool edge = false;
    exponent_at_t = ScanThenRefine([&](double e) { return ssr(t, e); }, exponents, 1e-6, &edge);
    exponent_at_edge = edge && exponent_at_t > 0.5 * options.max_profile_exponent;
    return ssr(t, exponent_at_t);
  };
  std::vector<double> distances;
  constexpr int kCoarseDistances = 80;
  for (int k = 0; k < kCoarseDistances; ++k) {
    distances.push_back(t0 * options.min_distance_factor *
                        std::pow(options.max_distance_factor / options.min_distance_factor,
                                 static_cast<double>(k) / (kCoarseDistances - 1)));
  }
  bool t_at_edge = false;
  const double t = ScanThenRefine(profiled, distances, 1e-6 * t0, &t_at_edge);
  const double ssr_min = profiled(t);
  const double exponent = fit.exponent_fitted ? exponent_at_t : start.profile_exponent;
  ssr(t, exponent);
  const Eigen::Vector3d b = last_solution;

  // 1-sigma of t: SSR(t) ~ SSR_min + H (t - t_fit)^2 / 2 near the minimum, s^2 = SSR_min / dof,
  // a change of SSR by s^2 is one sigma: sigma_t = sqrt(2 s^2 / H).
  const int unknowns = 4 + (fit.exponent_fitted ? 1 : 0);
  const double s2 = ssr_min / std::max(1, fit.samples - unknowns);
  const double h = 0.005 * t;
  const double curvature = (profiled(t + h) - 2.0 * ssr_min + profiled(t - h)) / (h * h);
  fit.distance_mm = t;
  fit.sigma_mm = curvature > 0.0 ? std::sqrt(2.0 * s2 / curvature) : std::numeric_limits<double>::infinity();
  fit.residual_rms = std::sqrt(ssr_min / fit.samples);
  fit.vignetting = {b[0] != 0.0 ? b[1] / b[0] : 0.0, b[0] != 0.0 ? b[2] / b[0] : 0.0};
  fit.model.position_in_world_mm = ray_origin_mm + t * r;
  if (fit.exponent_fitted) {
    fit.model.has_profile = exponent > 0.0;
    fit.model.profile_axis_in_world = (target_centre - fit.model.position_in_world_mm).normalized();
    fit.model.profile_exponent = exponent;
  }
  std::ostringstream reason;
  if (t_at_edge) {
    reason << frame_file << ": the shading is best explained at the edge of the distance search (" << t
           << " mm along the sphere's ray, searched " << distances.front() << "-" << distances.back() << " mm)";
  } else if (!(b[0] > 0.0)) {
    reason << frame_file << ": the shading fit gives a non-positive scale";
  } else if (exponent_at_edge) {
    reason << frame_file << ": the emitter's exponent runs to the edge of its search (" << exponent
           << "): distance and profile cannot be told apart";
  } else if (!(fit.sigma_mm <= options.max_relative_sigma * t)) {
    reason << frame_file << ": the distance is ill-conditioned (1-sigma " << fit.sigma_mm << " mm of " << t
           << " mm, more than " << options.max_relative_sigma * 100.0 << " %"
           << (fit.exponent_fitted ? "; distance and the fitted profile exponent trade off" : "") << ")";
  }
  fit.reason = reason.str();
  fit.ok = fit.reason.empty();
  if (!fit.ok) fit.model = start;
  return fit;
}

}  // namespace u3mscan
