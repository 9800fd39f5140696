#pragma once
// Camera geometry shared by the calibration steps: the pinhole + Brown-Conrady model of the capture
// contract (OpenCV convention: pixel centres at integer coordinates, a camera looks down its +z
// axis) with a world_from_camera pose. World frame: sample plane z = 0, +z toward the camera, mm.

#include <Eigen/Core>
#include <vector>

#include "capture/manifest.h"

namespace u3mscan {

// Everything needed to map between world points and pixels of one camera.
struct CameraModel {
  int width = 0;
  int height = 0;
  CameraIntrinsics intrinsics;
  std::array<double, 5> distortion{};  // k1, k2, p1, p2, k3
  CameraPose pose;                     // world_from_camera

  static CameraModel FromSpec(const CameraSpec& spec);  // pose: identity when the spec has none

  Eigen::Vector3d CentreInWorld() const { return pose.translation_mm; }
  // World point (mm) -> distorted pixel (OpenCV convention). `in_front` is false for points behind
  // the camera (the pixel is then meaningless).
  Eigen::Vector2d Project(const Eigen::Vector3d& point_in_world_mm, bool* in_front = nullptr) const;
  // Many points at once (cv::projectPoints); same convention as Project.
  void ProjectMany(const std::vector<Eigen::Vector3d>& points_in_world_mm, std::vector<Eigen::Vector2d>& pixels) const;
  // Distorted pixel -> unit ray direction in world (from the camera centre).
  Eigen::Vector3d PixelRayInWorld(const Eigen::Vector2d& pixel) const;
  // Distorted pixel -> point where its ray meets the plane z = plane_z_mm. Returns false when the
  // ray is parallel to the plane or meets it behind the camera.
  bool PixelToPlane(const Eigen::Vector2d& pixel, double plane_z_mm, Eigen::Vector3d* point_in_world_mm) const;
  // Pixel pitch (mm per pixel) on the plane z = 0 near `point_in_world_mm`: the geometric mean of
  // the footprint of one pixel there.
  double PitchOnPlaneMm(const Eigen::Vector3d& point_in_world_mm) const;
  bool HasDistortion() const;
};

// A camera looking straight down (+z of the camera = -z of the world, image rows along -y):
// world_from_camera rotation diag(1, -1, -1).
Eigen::Matrix3d LookingStraightDownRotation();

}  // namespace u3mscan
