#pragma once
// Stack: the calibrated, rectified data of one side of a capture, as photometric stereo and the
// fitter consume it. Produced by capture/ (calibration + rectification); lives in core so that
// reconstruction/ and fitting/ need nothing but core.
//
// Frames (capture contract, docs/capture-format.md): world z = 0 is the sample plane, +z toward the
// camera, +x right and +y up in the finished maps. Lengths in mm.

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "core/image.h"

namespace u3mscan {

// The metric grid of the finished maps. Pixel (col 0, row 0) is the top-left of the region; its
// centre is at (x0_mm + p/2, y1_mm - p/2), columns grow with +x, rows grow with -y.
struct MetricGrid {
  int width = 0;
  int height = 0;
  double pitch_mm = 0.0;  // p = 25.4 / dpi
  double x0_mm = 0.0;     // left edge of the region
  double y1_mm = 0.0;     // top edge of the region

  double dpi() const { return 25.4 / pitch_mm; }
  Eigen::Vector3d PixelCentreInWorld(int col, int row, double height_mm = 0.0) const {
    return {x0_mm + (col + 0.5) * pitch_mm, y1_mm - (row + 0.5) * pitch_mm, height_mm};
  }
};

enum class LightType { kDirectional, kPoint };

// One light as calibrated. Irradiance it gives a surface point x (before the cosine):
//   directional: intensity_rgb
//   point:       intensity_rgb * profile(x) / |position - x|^2,
//                profile = max(0, axis . (x - position)/|x - position|)^exponent (1 without profile).
struct LightModel {
  std::string id;
  LightType type = LightType::kDirectional;
  Eigen::Vector3d direction_in_world = Eigen::Vector3d::UnitZ();  // unit, sample -> light
  Eigen::Vector3d position_in_world_mm = Eigen::Vector3d::Zero();
  Eigen::Vector3d intensity_rgb = Eigen::Vector3d::Ones();
  bool has_profile = false;
  Eigen::Vector3d profile_axis_in_world = -Eigen::Vector3d::UnitZ();  // unit, light -> scene
  double profile_exponent = 0.0;

  // Unit vector from `point_in_world_mm` toward the light.
  Eigen::Vector3d DirectionFrom(const Eigen::Vector3d& point_in_world_mm) const;
  // Irradiance (before the cosine) relative to intensity_rgb: 1 for a directional light,
  // profile / d^2 (1/mm^2) for a point light.
  double RelativeIrradianceAt(const Eigen::Vector3d& point_in_world_mm) const;
};

// A camera looking at the stack's grid: only its centre matters after rectification (view vectors).
struct ViewGeometry {
  std::string camera_id;
  Eigen::Vector3d centre_in_world_mm = Eigen::Vector3d(0, 0, 1000);
};

// Per-pixel flags of an observation; a pixel with any flag set is not data.
enum ObservationFlag : std::uint8_t {
  kSaturated = 1u << 0,    // at or above the sensor's white level in any channel
  kOutOfView = 1u << 1,    // the camera does not see this point of the grid
  kCastShadow = 1u << 2,   // known to lie in a cast shadow (mask, or found by a later stage)
};

// One (view, light) image on the grid.
struct Observation {
  int view = 0;   // index into Stack::views
  int light = 0;  // index into Stack::lights
  // Linear RGB divided by exposure time and by the light's intensity_rgb, so that for a surface of
  // BRDF f: rgb = f(wi, wo) * cos(theta_i) * relative_irradiance.
  Image rgb;
  // Measured relative irradiance per pixel from flat frames (1 channel, units of
  // LightModel::RelativeIrradianceAt); empty when the analytic light model is to be used.
  Image irradiance;
  std::vector<std::uint8_t> flags;  // width*height ObservationFlag bits; empty = all valid
};

struct Stack {
  std::string side = "front";
  MetricGrid grid;
  std::vector<LightModel> lights;
  std::vector<ViewGeometry> views;
  std::vector<Observation> observations;
};

}  // namespace u3mscan
