#include "capture/light_calibration.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "capture/opencv_bridge.h"
#include "core/error.h"
#include "core/units.h"

namespace u3mscan {
namespace {

// FitPointLight: the distance from a sphere to its light that the weights and the plausibility
// check take as the least, as a fraction of the manifest's distance (a manifest off by half the
// rig's size is not a manifest of this rig).
constexpr double kMinDistanceOfManifest = 0.5;
// FitPointLight: a sphere's reflected ray that passes farther from the fitted light than this
// fraction of its distance (~1.1 deg) is a misplaced highlight, not noise (the highlights of a
// sphere 8 px across agree to ~0.3 deg).
constexpr double kMaxRayMissOfDistance = 0.02;

// The point of a sphere's reflected ray nearest to the manifest's light position: the direction
// from the sphere, the distance along the ray from the manifest. Averaged over several rays, the
// same for each.
Eigen::Vector3d ManifestDistanceAlongRays(const std::vector<SphereObservation>& observations, const LightModel& start) {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (const auto& o : observations) {
    const double along = std::max(0.0, o.reflected_in_world.dot(start.position_in_world_mm - o.highlight_point_in_world_mm));
    sum += o.highlight_point_in_world_mm + along * o.reflected_in_world;
  }
  return sum / static_cast<double>(observations.size());
}

float SampleBilinear(const cv::Mat& grey, double x, double y) {
  x = std::clamp(x, 0.0, grey.cols - 1.001);
  y = std::clamp(y, 0.0, grey.rows - 1.001);
  const int x0 = static_cast<int>(x), y0 = static_cast<int>(y);
  const double fx = x - x0, fy = y - y0;
  const float* r0 = grey.ptr<float>(y0);
  const float* r1 = grey.ptr<float>(y0 + 1);
  return static_cast<float>((1 - fy) * ((1 - fx) * r0[x0] + fx * r0[x0 + 1]) +
                            fy * ((1 - fx) * r1[x0] + fx * r1[x0 + 1]));
}

// Nearest intersection of the ray origin + s*dir (s > 0) with the sphere; false when it misses.
bool IntersectSphere(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, const Eigen::Vector3d& centre,
                     double radius, Eigen::Vector3d* hit) {
  const Eigen::Vector3d oc = origin - centre;
  const double b = oc.dot(dir);
  const double c = oc.squaredNorm() - radius * radius;
  const double discriminant = b * b - c;
  if (discriminant < 0.0) return false;
  const double s = -b - std::sqrt(discriminant);
  if (s <= 0.0) return false;
  *hit = origin + s * dir;
  return true;
}

// Apparent radius (px) of a sphere of radius_mm centred at `centre` (small-angle, at the image
// of the centre).
double ApparentRadiusPx(const CameraModel& camera, const Eigen::Vector3d& centre, double radius_mm) {
  const double distance = (centre - camera.CentreInWorld()).norm();
  const double half_angle = std::asin(std::min(1.0, radius_mm / std::max(distance, radius_mm)));
  return 0.5 * (camera.intrinsics.fx + camera.intrinsics.fy) * std::tan(half_angle);
}

// Sphere search: Hough circle on the display image, sub-pixel rim along radial profiles, then the
// 3D centre whose tangent cone fits the rim rays (Gauss-Newton on 3 unknowns).
Eigen::Vector3d FindSphere(const cv::Mat& grey, const cv::Mat& grey8, const CameraModel& camera,
                           const SphereTarget& sphere, const std::string& frame_file,
                           const std::optional<double>& centre_height_mm, double* edge_residual_px) {
  // Expected size from a sphere resting on the sample plane below the image centre.
  Eigen::Vector3d guess_centre;
  const Eigen::Vector2d image_centre(camera.intrinsics.cx, camera.intrinsics.cy);
  if (!camera.PixelToPlane(image_centre, sphere.radius_mm, &guess_centre)) {
    throw InputError(frame_file, "", "a camera that sees the sample plane (for the mirror-sphere search)");
  }
  const double expected_px = ApparentRadiusPx(camera, guess_centre, sphere.radius_mm);
  cv::Mat blurred;
  cv::GaussianBlur(grey8, blurred, cv::Size(5, 5), 1.5);
  std::vector<cv::Vec3f> circles;
  // A coarser accumulator for large spheres: the circle only seeds the sub-pixel rim trace.
  const double accumulator_ratio = std::max(1.0, expected_px / 40.0);
  cv::HoughCircles(blurred, circles, cv::HOUGH_GRADIENT, accumulator_ratio, expected_px, 100, 20,
                   static_cast<int>(0.6 * expected_px), static_cast<int>(1.5 * expected_px + 1));
  std::ostringstream what;
  what << "a mirror sphere of radius " << sphere.radius_mm << " mm (about " << std::lround(expected_px)
       << " px across its radius) standing out from its background";
  if (circles.empty()) throw InputError(frame_file, "", what.str() + "; no circle found");
  // Sub-pixel rim: the strongest step of each radial profile around (u0, v0), refined by a
  // parabola; rim points far from the median radius (a highlight or a shadow on the rim) dropped.
  constexpr int kAngles = 360;
  constexpr double kStepPx = 0.25;
  auto trace = [&](double u0, double v0, double rho0) {
    std::vector<Eigen::Vector2d> rim;
    std::vector<double> rim_radius;
    const int samples = static_cast<int>(0.6 * rho0 / kStepPx);
    const double start = 0.7 * rho0;
    std::vector<double> profile(std::max(samples, 0));
    for (int a = 0; a < kAngles; ++a) {
      const double angle = 2.0 * kPi * a / kAngles;
      const double ca = std::cos(angle), sa = std::sin(angle);
      for (int k = 0; k < samples; ++k) {
        const double r = start + k * kStepPx;
        profile[k] = SampleBilinear(grey, u0 + r * ca, v0 + r * sa);
      }
      auto gradient = [&](int k) { return std::abs(profile[k + 2] + profile[k + 1] - profile[k - 1] - profile[k - 2]); };
      int best = -1;
      double best_gradient = 0.0;
      for (int k = 2; k + 2 < samples; ++k) {
        const double g = gradient(k);
        if (g > best_gradient) best_gradient = g, best = k;
      }
      if (best < 3 || best + 3 >= samples) continue;
      const double gm = gradient(best - 1), g0 = gradient(best), gp = gradient(best + 1);
      const double denominator = gm - 2.0 * g0 + gp;
      const double offset = std::abs(denominator) > 1e-12 ? std::clamp(0.5 * (gm - gp) / denominator, -0.5, 0.5) : 0.0;
      const double r = start + (best + offset) * kStepPx;
      rim.emplace_back(u0 + r * ca, v0 + r * sa);
      rim_radius.push_back(r);
    }
    std::vector<Eigen::Vector3d> rays;
    if (rim.size() < kAngles / 2) return rays;
    std::vector<double> sorted = rim_radius;
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    const double median = sorted[sorted.size() / 2];
    for (std::size_t i = 0; i < rim.size(); ++i) {
      if (std::abs(rim_radius[i] - median) < 1.5) rays.push_back(camera.PixelRayInWorld(rim[i]));
    }
    return rays;
  };

  const Eigen::Vector3d origin = camera.CentreInWorld();
  const double f = 0.5 * (camera.intrinsics.fx + camera.intrinsics.fy);
  // With the height known, only x and y are fitted: the apparent size fixes the sphere's distance
  // only to about rim accuracy / radius in px (a hundredth of a pixel is 0.1 mm at 400 mm).
  const int unknowns = centre_height_mm ? 2 : 3;
  // The centre whose cone of tangent rays fits the rim rays: Gauss-Newton, then rim points beyond
  // 3 robust sigmas (at least a tenth of a pixel) dropped and the fit repeated.
  auto fit = [&](Eigen::Vector3d centre, std::vector<Eigen::Vector3d> rays) {
    auto residuals = [&](const Eigen::Vector3d& c) {
      Eigen::VectorXd r(rays.size());
      for (std::size_t i = 0; i < rays.size(); ++i) r[i] = (c - origin).cross(rays[i]).norm() - sphere.radius_mm;
      return r;
    };
    auto solve = [&](Eigen::Vector3d c) {
      for (int iteration = 0; iteration < 30; ++iteration) {
        const Eigen::VectorXd r = residuals(c);
        Eigen::MatrixXd jacobian(rays.size(), unknowns);
        for (int k = 0; k < unknowns; ++k) {
          Eigen::Vector3d step = Eigen::Vector3d::Zero();
          step[k] = 1e-4;
          jacobian.col(k) = (residuals(c + step) - r) / 1e-4;
        }
        const Eigen::VectorXd solved = jacobian.colPivHouseholderQr().solve(-r);
        Eigen::Vector3d delta = Eigen::Vector3d::Zero();
        delta.head(unknowns) = solved;
        c += delta;
        if (delta.norm() < 1e-9) break;
      }
      return c;
    };
    const double px_per_mm_at_sphere = f / (centre - origin).norm();
    for (int round = 0; round < 3; ++round) {
      centre = solve(centre);
      const Eigen::VectorXd r = residuals(centre);
      std::vector<double> abs_r(r.size());
      for (Eigen::Index i = 0; i < r.size(); ++i) abs_r[i] = std::abs(r[i]);
      std::vector<double> sorted_r = abs_r;
      std::nth_element(sorted_r.begin(), sorted_r.begin() + sorted_r.size() / 2, sorted_r.end());
      const double limit = std::max(0.1 / px_per_mm_at_sphere, 3.0 * 1.4826 * sorted_r[sorted_r.size() / 2]);
      std::vector<Eigen::Vector3d> kept;
      for (std::size_t i = 0; i < rays.size(); ++i) {
        if (abs_r[i] <= limit) kept.push_back(rays[i]);
      }
      if (kept.size() < kAngles / 3 || kept.size() == rays.size()) break;
      rays = std::move(kept);
    }
    centre = solve(centre);
    const Eigen::VectorXd r = residuals(centre);
    *edge_residual_px = std::sqrt(r.squaredNorm() / r.size()) * f / (centre - origin).norm();
    return centre;
  };

  // Round 1 from the Hough circle; round 2 traces the rim again around the fitted sphere's image,
  // so that the result does not depend on how well the circle was seeded.
  double u0 = circles[0][0], v0 = circles[0][1], rho0 = circles[0][2];
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  for (int round = 0; round < 2; ++round) {
    const std::vector<Eigen::Vector3d> rays = trace(u0, v0, rho0);
    if (rays.size() < kAngles / 3) {
      throw InputError(frame_file, "", what.str() + "; its rim could not be traced (not round, or too faint)");
    }
    if (round == 0) {
      // Start: the ray through the circle's centre, at the known height or at the distance the
      // apparent radius implies.
      const Eigen::Vector3d ray = camera.PixelRayInWorld(Eigen::Vector2d(u0, v0));
      centre = origin + sphere.radius_mm / std::sin(std::atan(rho0 / f)) * ray;
      if (centre_height_mm && std::abs(ray.z()) > 1e-9) {
        centre = origin + ((*centre_height_mm - origin.z()) / ray.z()) * ray;
        centre.z() = *centre_height_mm;
      }
    }
    centre = fit(centre, rays);
    const Eigen::Vector2d image_centre_px = camera.Project(centre);
    u0 = image_centre_px.x(), v0 = image_centre_px.y();
    rho0 = ApparentRadiusPx(camera, centre, sphere.radius_mm);
  }
  return centre;
}

}  // namespace

SphereObservation ObserveSphere(const Image& frame_rgb, const CameraModel& camera, const SphereTarget& sphere,
                                const std::string& frame_file, const std::optional<Eigen::Vector3d>& known_centre,
                                const std::optional<double>& centre_height_mm, bool refine_highlight) {
  if (!(sphere.radius_mm > 0.0)) {
    throw InputError(frame_file, "/targets/sphere/radius_mm", "a positive sphere radius in mm");
  }
  const cv::Mat grey = internal::GreyCopy(frame_rgb);
  double max_value = 0.0;
  cv::minMaxLoc(grey, nullptr, &max_value);
  SphereObservation observation;
  observation.frame_file = frame_file;
  observation.radius_mm = sphere.radius_mm;
  if (known_centre) {
    observation.centre_in_world_mm = *known_centre;
  } else {
    // The display image is stretched to the background so the dark sphere stands out against it.
    const double white = std::max(1e-6, internal::Quantile(grey, 0.90));
    observation.centre_in_world_mm =
        FindSphere(grey, internal::ToDisplay8(grey, white), camera, sphere, frame_file, centre_height_mm,
                   &observation.edge_residual_px);
    observation.centre_found_in_frame = true;
  }

  // Highlight: the brightest pixel inside the sphere's image, then the weighted centroid of the
  // bright blob connected to it (sub-pixel; a saturated plateau gives its centre).
  bool in_front = false;
  const Eigen::Vector2d centre_px = camera.Project(observation.centre_in_world_mm, &in_front);
  const double radius_px = ApparentRadiusPx(camera, observation.centre_in_world_mm, sphere.radius_mm);
  const std::string what = "a specular highlight on the mirror sphere (radius " + std::to_string(sphere.radius_mm) +
                           " mm, image centre " + std::to_string(std::lround(centre_px.x())) + "," +
                           std::to_string(std::lround(centre_px.y())) + " px)";
  if (!in_front) throw InputError(frame_file, "/targets/sphere/center_mm", "a sphere in front of the camera");
  cv::Mat disc = cv::Mat::zeros(grey.size(), CV_8U);
  cv::circle(disc, cv::Point(static_cast<int>(std::lround(centre_px.x())), static_cast<int>(std::lround(centre_px.y()))),
             static_cast<int>(0.97 * radius_px), cv::Scalar(255), cv::FILLED);
  double peak = 0.0;
  cv::Point peak_at;
  cv::minMaxLoc(grey, nullptr, &peak, nullptr, &peak_at, disc);
  const cv::Scalar disc_mean = cv::mean(grey, disc);
  if (cv::countNonZero(disc) == 0 || !(peak > 4.0 * disc_mean[0]) || !(peak > 0.0)) {
    throw InputError(frame_file, "", what + "; the sphere shows no highlight well above its mean");
  }
  // Weights above the sphere's typical (median) value, over the blob down to 5 % of the peak: a
  // highlight smaller than a pixel still has a sub-pixel centroid through its partial coverage.
  std::vector<float> inside;
  for (int row = 0; row < grey.rows; ++row) {
    for (int col = 0; col < grey.cols; ++col) {
      if (disc.at<unsigned char>(row, col)) inside.push_back(grey.at<float>(row, col));
    }
  }
  std::nth_element(inside.begin(), inside.begin() + inside.size() / 2, inside.end());
  const double background = inside[inside.size() / 2];
  const float threshold = static_cast<float>(background + 0.05 * (peak - background));
  cv::Mat bright = (grey >= threshold) & disc;
  cv::Mat labels;
  cv::connectedComponents(bright, labels, 8, CV_32S);
  const int label = labels.at<int>(peak_at);
  double sum_w = 0.0, sum_x = 0.0, sum_y = 0.0;
  int area = 0;
  for (int row = 0; row < grey.rows; ++row) {
    const int* l = labels.ptr<int>(row);
    const float* g = grey.ptr<float>(row);
    for (int col = 0; col < grey.cols; ++col) {
      if (l[col] != label) continue;
      const double w = g[col] - background;
      sum_w += w, sum_x += w * col, sum_y += w * row;
      ++area;
    }
  }
  observation.highlight_px = sum_w > 0 ? Eigen::Vector2d(sum_x / sum_w, sum_y / sum_w)
                                       : Eigen::Vector2d(peak_at.x, peak_at.y);
  if (refine_highlight) {
    // Refined: the centroid under a Gaussian window centred on itself (iterated to its fixed
    // point), over every pixel above the background, not only the thresholded blob. Cutting the
    // spot at a threshold on the pixel grid moves its centroid by a few hundredths of a pixel as
    // the spot moves within a pixel; a window symmetric about the result does not. Wide enough
    // (at least 2.5 px) that a spot of one or two pixels keeps its centroid (bias < 0.01 px).
    // Measured on the synthetic near rig (docs/calibration.md, "Joint fit"): with the true sphere
    // centres, worst point-light position 2.4 % from the blob's centroid, 0.30 % refined.
    const double sigma_w = std::max(2.5, 1.5 * std::sqrt(area / kPi));
    const int reach = static_cast<int>(std::ceil(3.0 * sigma_w));
    Eigen::Vector2d c = observation.highlight_px;
    for (int it = 0; it < 20; ++it) {
      double w_sum = 0, x_sum = 0, y_sum = 0;
      for (int row = std::max(0, static_cast<int>(c.y()) - reach); row <= std::min(grey.rows - 1, static_cast<int>(c.y()) + reach); ++row) {
        for (int col = std::max(0, static_cast<int>(c.x()) - reach); col <= std::min(grey.cols - 1, static_cast<int>(c.x()) + reach); ++col) {
          if (!disc.at<unsigned char>(row, col)) continue;
          const double v = grey.at<float>(row, col) - background;
          if (v <= 0) continue;
          const double d2 = (col - c.x()) * (col - c.x()) + (row - c.y()) * (row - c.y());
          const double w = v * std::exp(-0.5 * d2 / (sigma_w * sigma_w));
          w_sum += w, x_sum += w * col, y_sum += w * row;
        }
      }
      if (!(w_sum > 0)) break;
      const Eigen::Vector2d next(x_sum / w_sum, y_sum / w_sum);
      const bool done = (next - c).norm() < 1e-4;
      c = next;
      if (done) break;
    }
    observation.highlight_px = c;
  }
  const Eigen::Vector3d ray = camera.PixelRayInWorld(observation.highlight_px);
  Eigen::Vector3d hit;
  if (!IntersectSphere(camera.CentreInWorld(), ray, observation.centre_in_world_mm, sphere.radius_mm, &hit)) {
    throw InputError(frame_file, "", what + "; the highlight's ray misses the sphere");
  }
  const Eigen::Vector3d normal = (hit - observation.centre_in_world_mm).normalized();
  const Eigen::Vector3d to_camera = -ray;
  observation.highlight_point_in_world_mm = hit;
  observation.apparent_radius_px = radius_px;
  observation.highlight_area_px = area;
  observation.camera_centre_in_world_mm = camera.CentreInWorld();
  observation.reflected_in_world = (2.0 * normal.dot(to_camera) * normal - to_camera).normalized();
  return observation;
}

LightFit FitDirectionalLight(const std::vector<SphereObservation>& observations, const LightModel& start) {
  LightFit fit;
  fit.model = start;
  fit.model.type = LightType::kDirectional;
  fit.placements = static_cast<int>(observations.size());
  fit.residual_unit = "deg";
  if (observations.empty()) return fit;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (const auto& o : observations) sum += o.reflected_in_world;
  fit.model.direction_in_world = sum.normalized();
  double sum_sq = 0.0;
  for (const auto& o : observations) {
    const double angle = std::acos(std::clamp(o.reflected_in_world.dot(fit.model.direction_in_world), -1.0, 1.0));
    sum_sq += RadToDeg(angle) * RadToDeg(angle);
  }
  fit.residual = std::sqrt(sum_sq / observations.size());
  if (observations.size() == 1) fit.note = "one placement: no residual";
  return fit;
}

LightFit FitPointLight(const std::vector<SphereObservation>& observations, const LightModel& start,
                       const LightFitOptions& options) {
  LightFit fit;
  fit.model = start;
  fit.model.type = LightType::kPoint;
  fit.placements = static_cast<int>(observations.size());
  fit.residual_unit = "mm";
  if (observations.empty()) return fit;
  const bool prior = options.manifest_position_sigma_mm > 0.0;
  if (observations.size() == 1 && !prior) {
    fit.model.position_in_world_mm = ManifestDistanceAlongRays(observations, start);
    fit.note = "one placement: direction from the sphere, distance along the ray from the manifest";
    return fit;
  }
  // Minimise sum_i w_i |(I - l_i l_i^T)(X - P_i)|^2 + |X - X_manifest|^2 / sigma_m^2, with
  // w_i = 1 / (sigma_i d_i)^2: a ray's lateral uncertainty grows with the distance d_i along it.
  // The weights depend on X, so a few fixed-point rounds from the manifest's position. d_i is held
  // at no less than kMinDistanceOfManifest of the manifest's distance: spheres a few mm apart see a
  // light 400 mm away along nearly parallel lines whose least-squares meeting point can fall next
  // to the spheres, and there the weights (1/d^2) grew without bound and held it (synthetic near rig,
  // 64 px frames, 7 placements within 3 mm: 2 of 16 lights fitted 1-2 mm from the spheres, 400 mm
  // from the truth, each claiming a 1-sigma under 1 mm).
  Eigen::Vector3d x = start.position_in_world_mm;
  Eigen::Matrix3d a = Eigen::Matrix3d::Identity();
  for (int round = 0; round < 6; ++round) {
    a.setZero();
    Eigen::Vector3d b = Eigen::Vector3d::Zero();
    for (const auto& o : observations) {
      const Eigen::Matrix3d projector =
          Eigen::Matrix3d::Identity() - o.reflected_in_world * o.reflected_in_world.transpose();
      const double sigma_px = options.highlight_sigma_px / std::sqrt(std::max(1, o.highlight_area_px));
      const double sigma_rad = 2.0 * sigma_px / std::max(1.0, o.apparent_radius_px);
      const double manifest_distance = (start.position_in_world_mm - o.highlight_point_in_world_mm).norm();
      const double distance = std::max({1.0, (x - o.highlight_point_in_world_mm).norm(),
                                        kMinDistanceOfManifest * manifest_distance});
      const double w = 1.0 / (sigma_rad * sigma_rad * distance * distance);
      a += w * projector;
      b += w * projector * o.highlight_point_in_world_mm;
    }
    if (prior) {
      const double w = 1.0 / (options.manifest_position_sigma_mm * options.manifest_position_sigma_mm);
      a += w * Eigen::Matrix3d::Identity();
      b += w * start.position_in_world_mm;
    }
    x = a.ldlt().solve(b);
  }
  // A highlight found in the wrong place (a rim pixel, a reflection of the table on a sphere a few
  // pixels across) gives a ray that misses the light by degrees; the worst such ray is left out
  // and the rest fitted again, as long as two or more rays are there to compare (so one may
  // remain; with two, the prior decides which misses more) (synthetic near rig, 64 px frames: one
  // highlight of L08 and one of L11 put the fit 20 mm and 2.6-3.1 deg off, the rays missing the
  // fit by 41-42 mm RMS where the other lights' missed by 0.1-1.7 mm).
  if (observations.size() >= 2) {
    std::size_t worst = 0;
    double worst_miss_of_distance = 0.0;
    for (std::size_t i = 0; i < observations.size(); ++i) {
      const SphereObservation& o = observations[i];
      const Eigen::Vector3d d = x - o.highlight_point_in_world_mm;
      const double miss = (d - d.dot(o.reflected_in_world) * o.reflected_in_world).norm();
      const double of_distance = miss / std::max(1.0, d.norm());
      if (of_distance > worst_miss_of_distance) worst_miss_of_distance = of_distance, worst = i;
    }
    if (worst_miss_of_distance > kMaxRayMissOfDistance) {
      std::vector<SphereObservation> kept = observations;
      kept.erase(kept.begin() + static_cast<std::ptrdiff_t>(worst));
      LightFit refit = FitPointLight(kept, start, options);
      std::ostringstream note;
      note << observations[worst].frame_file << " left out (its ray missed the light fitted to every ray by "
           << RadToDeg(std::asin(std::min(1.0, worst_miss_of_distance))) << " deg); " << refit.note;
      refit.note = note.str();
      return refit;
    }
  }
  // The lines extend both ways; a light lies ahead of every sphere along its reflected ray, at a
  // distance of the manifest's order. A meeting point behind a sphere or next to it, or one whose
  // uncertainty is of the order of the distance itself (nearly parallel rays, no prior to hold the
  // distance), is no measurement of the distance: the direction is kept and the distance along
  // each ray is the manifest's.
  double manifest_distance = 0.0;
  bool ahead = true;
  for (const auto& o : observations) {
    const double d = (start.position_in_world_mm - o.highlight_point_in_world_mm).norm();
    manifest_distance = std::max(manifest_distance, d);
    ahead = ahead && (x - o.highlight_point_in_world_mm).dot(o.reflected_in_world) >= kMinDistanceOfManifest * d;
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(a.inverse());
  const double sigma_mm = std::sqrt(std::max(0.0, eigen.eigenvalues().maxCoeff()));
  const bool distance_from_manifest = !ahead || sigma_mm > kMinDistanceOfManifest * manifest_distance;
  if (distance_from_manifest) {
    x = ManifestDistanceAlongRays(observations, start);
    fit.note = !ahead ? "the reflected rays meet behind or next to the spheres" : "the reflected rays are nearly parallel";
    fit.note += " (too short a baseline for the distance): direction from the spheres, distance along the rays from "
                "the manifest";
    fit.position_sigma_mm = options.manifest_position_sigma_mm;  // the distance is the manifest's (0: no prior given)
  }
  fit.model.position_in_world_mm = x;
  double sum_sq = 0.0;
  for (const auto& o : observations) {
    const Eigen::Vector3d d = x - o.highlight_point_in_world_mm;
    sum_sq += (d - d.dot(o.reflected_in_world) * o.reflected_in_world).squaredNorm();
  }
  fit.residual = std::sqrt(sum_sq / observations.size());
  if (distance_from_manifest) return fit;
  fit.position_sigma_mm = sigma_mm;
  std::ostringstream note;
  note << "position 1-sigma " << fit.position_sigma_mm << " mm";
  if (prior) note << " (manifest prior " << options.manifest_position_sigma_mm << " mm)";
  fit.note = note.str();
  return fit;
}

}  // namespace u3mscan
