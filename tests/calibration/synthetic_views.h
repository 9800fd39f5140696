#pragma once
// Test-only renderer of calibration views with known truth: a ChArUco board, a mirror sphere
// under one light, a white target and a 24-patch chart on the sample plane, seen through a
// CameraModel (distortion included), supersampled so edges are anti-aliased as in a photograph.

#include <Eigen/Core>
#include <functional>

#include "capture/camera_model.h"
#include "capture/manifest.h"
#include "core/image.h"

namespace u3mscan::testing {

// A camera `height_mm` above the origin looking straight down; focal length so that the image
// spans `field_mm` across its width.
CameraModel DownCamera(int width, int height, double height_mm, double field_mm);
// The same camera tilted about the world x axis by tilt_deg (looking at the origin).
CameraModel TiltedCamera(int width, int height, double distance_mm, double field_mm, double tilt_deg,
                         double yaw_deg = 0.0);

// Renders `radiance(point_on_plane)` for rays hitting z = 0 (3 channels), `supersample`^2 rays per
// pixel. Pixels whose rays miss the plane get 0.
Image RenderPlane(const CameraModel& camera, const std::function<Eigen::Vector3d(const Eigen::Vector3d&)>& radiance,
                  int supersample = 3);

// A ChArUco board (white 0.8, black 0.04) on a grey (0.3) table.
Image RenderBoard(const CameraModel& camera, const BoardTarget& board, int supersample = 3);

// A mirror sphere (environment 0.02, emitter 1.0) on a plane of grey 0.4. The light is either a
// direction (`point_light` false: a distant disc of angular radius emitter_deg) or a point at
// `light` (a ball of radius emitter_mm).
Image RenderSphere(const CameraModel& camera, const Eigen::Vector3d& centre_mm, double radius_mm,
                   const Eigen::Vector3d& light, bool point_light, double emitter_size, int supersample = 3);

}  // namespace u3mscan::testing
