#pragma once
// Colour calibration: a 3x3 matrix from the camera's linear RGB to linear sRGB (D65), fitted by
// least squares in linear RGB on the 24 patches of a classic colour chart, judged in CIEDE2000
// (core/colour.h) before and after.
//
// The chart is found by OpenCV's mcc detector (its outer box; the two possible orientations are
// told apart by which fits the reference colours better), or, when mcc finds nothing, at a known
// layout on the sample plane (ChartLayout, docs/calibration.md).

#include <Eigen/Core>
#include <array>
#include <optional>
#include <string>
#include <vector>

#include "capture/camera_model.h"
#include "core/colour.h"
#include "core/image.h"

namespace u3mscan {

// Reference linear sRGB of the classic 24-patch chart (the published sRGB values, linearised),
// row-major as the chart is read: row 0 = dark skin ... bluish green, row 3 = white ... black.
const std::array<Rgb, 24>& ClassicChartLinearSrgb();

// Where the chart lies on the sample plane when no detector finds it: 6 x 4 patches, row 0 at
// +y, column 0 at -x, centred on `centre_mm`, `patch_pitch_mm` apart (0 = unknown: searched).
struct ChartLayout {
  Eigen::Vector2d centre_mm = Eigen::Vector2d::Zero();
  double patch_pitch_mm = 0.0;
};

struct ChartPatch {
  Eigen::Vector2d centre_px = Eigen::Vector2d::Zero();  // in the camera frame
  Rgb mean_rgb{};                                       // frame units, central part of the patch
};

// The 24 patches at the layout, seen by `camera`. Throws InputError naming the frame when a patch
// lies outside the view.
std::vector<ChartPatch> MeasureChartAtLayout(const Image& frame_rgb, const CameraModel& camera,
                                             const ChartLayout& layout, const std::string& frame_file);
// The patch pitch (mm) of a chart centred on `centre_mm` whose patch means a 3x3 matrix maps onto
// the reference best: a coarse-to-fine search between 6 camera pixels and a sixth of the view.
// Returns 0 when no pitch puts the whole chart in view.
double FindChartPitchMm(const Image& frame_rgb, const CameraModel& camera, const Eigen::Vector2d& centre_mm);

// The 24 patches found by cv::mcc (nullopt when it finds no chart). `reference` orders the two
// possible orientations: the one whose 3x3 fit leaves the smaller residual wins.
std::optional<std::vector<ChartPatch>> MeasureChartWithMcc(const Image& frame_rgb);

struct ColourFit {
  Eigen::Matrix3d matrix = Eigen::Matrix3d::Identity();  // linear sRGB = matrix * camera RGB
  double delta_e_before_mean = 0, delta_e_before_max = 0;  // CIEDE2000, measured vs reference
  double delta_e_after_mean = 0, delta_e_after_max = 0;
  double rms_rgb_after = 0;  // linear RGB residual of the fit
  // Leave-one-out: each patch corrected by the matrix fitted to the other patches, mean CIEDE2000.
  // What the matrix does to colours it was not fitted to; the in-sample `after` always looks
  // better than `before`, even when the matrix only bends to fit bad patch readings.
  double delta_e_cross_validated_mean = 0;
};

// Size of the chart in the frame: the median distance (px) between the centres of neighbouring
// patches (along rows and columns). 0 when fewer than two patches.
double ChartPatchPitchPx(const std::vector<ChartPatch>& patches);

// Least squares: min sum |M m_i - r_i|^2 over the patches (measured in reflectance units).
ColourFit FitColourCorrection(const std::vector<Rgb>& measured, const std::vector<Rgb>& reference);

}  // namespace u3mscan
