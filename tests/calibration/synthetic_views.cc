#include "synthetic_views.h"

#include <Eigen/Geometry>
#include <cmath>
#include <random>
#include <opencv2/aruco/charuco.hpp>

#include "core/parallel.h"
#include "core/units.h"

namespace u3mscan::testing {

CameraModel DownCamera(int width, int height, double height_mm, double field_mm) {
  CameraModel camera;
  camera.width = width;
  camera.height = height;
  const double f = width * height_mm / field_mm;
  camera.intrinsics = {f, f, (width - 1) / 2.0, (height - 1) / 2.0};
  camera.pose.rotation = LookingStraightDownRotation();
  camera.pose.translation_mm = Eigen::Vector3d(0, 0, height_mm);
  return camera;
}

CameraModel TiltedCamera(int width, int height, double distance_mm, double field_mm, double tilt_deg,
                         double yaw_deg) {
  CameraModel camera = DownCamera(width, height, distance_mm, field_mm);
  // Tilt about world x (camera moves toward -y, still looking at the origin), then yaw about z.
  const Eigen::Matrix3d tilt = Eigen::AngleAxisd(DegToRad(tilt_deg), Eigen::Vector3d::UnitX()).toRotationMatrix();
  const Eigen::Matrix3d yaw = Eigen::AngleAxisd(DegToRad(yaw_deg), Eigen::Vector3d::UnitZ()).toRotationMatrix();
  camera.pose.rotation = yaw * tilt * camera.pose.rotation;
  camera.pose.translation_mm = yaw * tilt * Eigen::Vector3d(0, 0, distance_mm);
  return camera;
}

namespace {

// Stratified, jittered supersampling (fixed seed per row): the expected pixel value is the exact
// coverage, so edges land where the geometry says rather than on a 1/supersample lattice. The lens
// is linearised within each pixel (three undistortions per pixel instead of one per ray).
template <typename Shade>
Image RenderRays(const CameraModel& camera, int supersample, const Shade& shade) {
  Image image(camera.width, camera.height, 3);
  const int n = supersample * 2;  // strata per axis
  ParallelFor(camera.height, [&](std::size_t begin, std::size_t end) {
    for (std::size_t row = begin; row < end; ++row) {
      std::mt19937 rng(static_cast<unsigned>(1234 + row));
      std::uniform_real_distribution<double> jitter(0.0, 1.0);
      auto normalised = [&](double col, double r) {
        const Eigen::Vector3d ray = camera.pose.rotation.transpose() * camera.PixelRayInWorld({col, r});
        return Eigen::Vector2d(ray.x() / ray.z(), ray.y() / ray.z());
      };
      for (int col = 0; col < camera.width; ++col) {
        const Eigen::Vector2d n0 = normalised(col, static_cast<double>(row));
        const Eigen::Vector2d dx = normalised(col + 1.0, static_cast<double>(row)) - n0;
        const Eigen::Vector2d dy = normalised(col, row + 1.0) - n0;
        Eigen::Vector3d sum = Eigen::Vector3d::Zero();
        for (int sy = 0; sy < n; ++sy) {
          for (int sx = 0; sx < n; ++sx) {
            const double ox = (sx + jitter(rng)) / n - 0.5, oy = (sy + jitter(rng)) / n - 0.5;
            const Eigen::Vector2d xy = n0 + ox * dx + oy * dy;
            const Eigen::Vector3d ray = (camera.pose.rotation * Eigen::Vector3d(xy.x(), xy.y(), 1.0)).normalized();
            sum += shade(camera.CentreInWorld(), ray);
          }
        }
        sum /= n * n;
        for (int c = 0; c < 3; ++c) image.at(c, static_cast<int>(row), col) = static_cast<float>(sum[c]);
      }
    }
  });
  return image;
}

bool HitPlane(const Eigen::Vector3d& origin, const Eigen::Vector3d& ray, Eigen::Vector3d* hit) {
  if (std::abs(ray.z()) < 1e-12) return false;
  const double s = -origin.z() / ray.z();
  if (s <= 0) return false;
  *hit = origin + s * ray;
  return true;
}

}  // namespace

Image RenderPlane(const CameraModel& camera, const std::function<Eigen::Vector3d(const Eigen::Vector3d&)>& radiance,
                  int supersample) {
  return RenderRays(camera, supersample, [&](const Eigen::Vector3d& origin, const Eigen::Vector3d& ray) {
    Eigen::Vector3d hit;
    return HitPlane(origin, ray, &hit) ? radiance(hit) : Eigen::Vector3d::Zero();
  });
}

Image RenderBoard(const CameraModel& camera, const BoardTarget& board, int supersample) {
  const auto dictionary = cv::aruco::getPredefinedDictionary(cv::aruco::DICT_5X5_100);
  const auto charuco = cv::aruco::CharucoBoard::create(board.squares_x, board.squares_y,
                                                       static_cast<float>(board.square_mm),
                                                       static_cast<float>(board.marker_mm), dictionary);
  constexpr double kTexelsPerMm = 40.0;
  const double width_mm = board.squares_x * board.square_mm, height_mm = board.squares_y * board.square_mm;
  cv::Mat texture;
  charuco->draw(cv::Size(static_cast<int>(width_mm * kTexelsPerMm), static_cast<int>(height_mm * kTexelsPerMm)),
                texture, 0, 1);
  return RenderPlane(camera, [&](const Eigen::Vector3d& p) -> Eigen::Vector3d {
    // World -> board (docs/calibration.md): x_b = x + W/2, y_b = H/2 - y.
    const double xb = p.x() + width_mm / 2, yb = height_mm / 2 - p.y();
    if (xb < 0 || yb < 0 || xb >= width_mm || yb >= height_mm) return Eigen::Vector3d::Constant(0.3);
    const int u = static_cast<int>(xb * kTexelsPerMm), v = static_cast<int>(yb * kTexelsPerMm);
    const bool white = texture.at<unsigned char>(std::min(v, texture.rows - 1), std::min(u, texture.cols - 1)) > 127;
    return Eigen::Vector3d::Constant(white ? 0.8 : 0.04);
  }, supersample);
}

Image RenderSphere(const CameraModel& camera, const Eigen::Vector3d& centre_mm, double radius_mm,
                   const Eigen::Vector3d& light, bool point_light, double emitter_size, int supersample) {
  const double cos_emitter = std::cos(DegToRad(emitter_size));
  return RenderRays(camera, supersample, [&](const Eigen::Vector3d& origin, const Eigen::Vector3d& ray) {
    const Eigen::Vector3d oc = origin - centre_mm;
    const double b = oc.dot(ray), c = oc.squaredNorm() - radius_mm * radius_mm, disc = b * b - c;
    if (disc >= 0 && -b - std::sqrt(disc) > 0) {
      const Eigen::Vector3d hit = origin + (-b - std::sqrt(disc)) * ray;
      const Eigen::Vector3d n = (hit - centre_mm).normalized();
      const Eigen::Vector3d reflected = ray - 2.0 * ray.dot(n) * n;
      bool lit = false;
      if (point_light) {
        const Eigen::Vector3d to_light = light - hit;
        const double along = to_light.dot(reflected);
        lit = along > 0 && (to_light - along * reflected).norm() < emitter_size;
      } else {
        lit = reflected.dot(light.normalized()) > cos_emitter;
      }
      return Eigen::Vector3d::Constant(lit ? 1.0 : 0.02);
    }
    Eigen::Vector3d hit;
    return HitPlane(origin, ray, &hit) ? Eigen::Vector3d::Constant(0.4) : Eigen::Vector3d::Zero();
  });
}

}  // namespace u3mscan::testing
