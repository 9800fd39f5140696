#include "capture/camera_model.h"

#include <Eigen/Dense>
#include <cmath>

namespace u3mscan {
namespace {

// Brown-Conrady distortion of normalised image coordinates (OpenCV's 5-coefficient model).
Eigen::Vector2d Distort(const std::array<double, 5>& d, const Eigen::Vector2d& xy) {
  const double x = xy.x(), y = xy.y();
  const double r2 = x * x + y * y;
  const double radial = 1.0 + r2 * (d[0] + r2 * (d[1] + r2 * d[4]));
  return {x * radial + 2.0 * d[2] * x * y + d[3] * (r2 + 2.0 * x * x),
          y * radial + d[2] * (r2 + 2.0 * y * y) + 2.0 * d[3] * x * y};
}

// Inverse of Distort by Newton's method (numerical Jacobian); converges in a few steps for every
// lens a scanner uses, and to far below a thousandth of a pixel.
Eigen::Vector2d Undistort(const std::array<double, 5>& d, const Eigen::Vector2d& distorted) {
  Eigen::Vector2d xy = distorted;
  constexpr double kStep = 1e-7;
  for (int iteration = 0; iteration < 30; ++iteration) {
    const Eigen::Vector2d residual = Distort(d, xy) - distorted;
    if (residual.squaredNorm() < 1e-28) break;
    Eigen::Matrix2d jacobian;
    jacobian.col(0) = (Distort(d, xy + Eigen::Vector2d(kStep, 0)) - Distort(d, xy)) / kStep;
    jacobian.col(1) = (Distort(d, xy + Eigen::Vector2d(0, kStep)) - Distort(d, xy)) / kStep;
    xy -= jacobian.partialPivLu().solve(residual);
  }
  return xy;
}

}  // namespace

CameraModel CameraModel::FromSpec(const CameraSpec& spec) {
  CameraModel model;
  model.width = spec.width;
  model.height = spec.height;
  model.intrinsics = spec.intrinsics;
  model.distortion = spec.distortion;
  if (spec.pose) model.pose = *spec.pose;
  return model;
}

Eigen::Vector2d CameraModel::Project(const Eigen::Vector3d& point_in_world_mm, bool* in_front) const {
  const Eigen::Vector3d p_cam = pose.rotation.transpose() * (point_in_world_mm - pose.translation_mm);
  if (in_front) *in_front = p_cam.z() > 0.0;
  const double z = std::abs(p_cam.z()) > 1e-12 ? p_cam.z() : 1e-12;
  const Eigen::Vector2d xy = Distort(distortion, Eigen::Vector2d(p_cam.x() / z, p_cam.y() / z));
  return {intrinsics.fx * xy.x() + intrinsics.cx, intrinsics.fy * xy.y() + intrinsics.cy};
}

void CameraModel::ProjectMany(const std::vector<Eigen::Vector3d>& points_in_world_mm,
                              std::vector<Eigen::Vector2d>& pixels) const {
  pixels.resize(points_in_world_mm.size());
  for (std::size_t i = 0; i < points_in_world_mm.size(); ++i) pixels[i] = Project(points_in_world_mm[i]);
}

Eigen::Vector3d CameraModel::PixelRayInWorld(const Eigen::Vector2d& pixel) const {
  const Eigen::Vector2d distorted((pixel.x() - intrinsics.cx) / intrinsics.fx,
                                  (pixel.y() - intrinsics.cy) / intrinsics.fy);
  const Eigen::Vector2d xy = HasDistortion() ? Undistort(distortion, distorted) : distorted;
  return (pose.rotation * Eigen::Vector3d(xy.x(), xy.y(), 1.0)).normalized();
}

bool CameraModel::PixelToPlane(const Eigen::Vector2d& pixel, double plane_z_mm,
                               Eigen::Vector3d* point_in_world_mm) const {
  const Eigen::Vector3d ray = PixelRayInWorld(pixel);
  if (std::abs(ray.z()) < 1e-12) return false;
  const double s = (plane_z_mm - pose.translation_mm.z()) / ray.z();
  if (s <= 0.0) return false;
  *point_in_world_mm = pose.translation_mm + s * ray;
  return true;
}

double CameraModel::PitchOnPlaneMm(const Eigen::Vector3d& point_in_world_mm) const {
  const Eigen::Vector2d pixel = Project(point_in_world_mm);
  Eigen::Vector3d a, b, c;
  if (!PixelToPlane(pixel, point_in_world_mm.z(), &a) ||
      !PixelToPlane(pixel + Eigen::Vector2d(1, 0), point_in_world_mm.z(), &b) ||
      !PixelToPlane(pixel + Eigen::Vector2d(0, 1), point_in_world_mm.z(), &c)) {
    return 0.0;
  }
  return std::sqrt((b - a).norm() * (c - a).norm());
}

bool CameraModel::HasDistortion() const {
  for (double k : distortion) {
    if (k != 0.0) return true;
  }
  return false;
}

Eigen::Matrix3d LookingStraightDownRotation() {
  return Eigen::Vector3d(1.0, -1.0, -1.0).asDiagonal();
}

}  // namespace u3mscan
