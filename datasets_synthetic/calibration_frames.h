#pragma once
// Calibration frames of the synthetic scanner, one renderer per role of the capture contract
// (docs/capture-format.md): dark, flat (white target), board (ChArUco), sphere (mirror ball),
// chart (24-patch ColorChecker). Ambient and backlight frames show the sample, so they come from
// SceneRenderer (renderer.h). Every frame is linear in decoded units, before the sensor.
//
// Targets are sized to the top camera's view and lie in the sample plane z = 0 centred on the
// origin (the sphere rests on it). World frame as in rig.h: +x right, +y up, mm.

#include <Eigen/Core>
#include <array>
#include <string>
#include <vector>

#include "core/image.h"
#include "datasets_synthetic/rig.h"

namespace u3mscan::synthetic {

// A ChArUco board as OpenCV's aruco module (4.6) defines it. Its object frame has the origin at the
// printed board's top-left outer corner, x along the squares_x side to the right, y along the
// squares_y side DOWN the print, z into the print; laid face up on the sample plane, that is
// world_from_board = [R = diag(1, -1, -1), t = (origin_x, origin_y, 0)]: a board point (X, Y, 0)
// is the world point (origin_x + X, origin_y - Y, 0).
struct BoardSpec {
  int squares_x = 5;
  int squares_y = 5;
  double square_mm = 10.0;
  double marker_mm = 7.0;
  std::string dictionary = "DICT_5X5_100";
  std::array<double, 2> origin_mm{};
};

struct CalibrationTargets {
  BoardSpec board;
  double white_reflectance = 0.9;  // the flat-field target, Lambertian
  double sphere_radius_mm = 10.0;
  // One placement for directional rigs, three for point lights (light positions are triangulated).
  std::vector<Eigen::Vector3d> sphere_centers_mm;
  double sphere_highlight_level = 0.8;  // decoded value of the mirrored emitter, below saturation
  std::array<double, 4> chart_rect_mm{};  // [x0, y0, x1, y1] of the chart's outer edge
  double chart_patch_mm = 10.0;
  double backlight_level = 0.7;  // decoded value of the bare light table
};

// Targets sized to rig.cameras[0]'s view of the sample plane.
CalibrationTargets MakeCalibrationTargets(const Rig& rig);

// The classic 24-patch ColorChecker, X-Rite's published sRGB (D65, 8-bit) values, row-major from
// "dark skin" (top-left) to "black" (bottom-right), 6 columns x 4 rows.
const std::array<std::array<int, 3>, 24>& ColorCheckerSrgb8();
// Linear-sRGB reflectance of patch k (0..23).
Eigen::Vector3d ColorCheckerLinear(int patch);

// Printed board as a 1-channel albedo texture (black 0.04, white 0.9) drawn with
// cv::aruco::CharucoBoard::draw; texel (0, 0) is the board's top-left corner (world max y).
Image DrawBoardTexture(const BoardSpec& board, int texels_per_square);
// The chart as a 3-channel linear albedo texture over chart_rect_mm.
Image DrawChartTexture(const CalibrationTargets& targets, int texels_per_patch);

// Frames (3 channels, camera size). `light_index` selects the light that is on.
Image RenderDarkFrame(const Rig& rig, int camera_index);
Image RenderFlatFrame(const Rig& rig, int camera_index, const CalibrationTargets& targets, int light_index);
Image RenderBoardFrame(const Rig& rig, int camera_index, const CalibrationTargets& targets, int light_index);
Image RenderSphereFrame(const Rig& rig, int camera_index, const CalibrationTargets& targets, int light_index,
                        int placement);
Image RenderChartFrame(const Rig& rig, int camera_index, const CalibrationTargets& targets, int light_index);

}  // namespace u3mscan::synthetic
