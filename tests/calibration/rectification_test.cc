#include "capture/rectification.h"

#include <gtest/gtest.h>

#include <iostream>

#include "capture/camera_calibration.h"
#include "core/units.h"
#include "synthetic_views.h"

namespace u3mscan {
namespace {

constexpr double kMaxScaleError = 0.001;        // issue 4: map scale within 0.1 % of the true dpi
constexpr double kMaxRegistrationErrorPx = 0.2;  // rectified corners against their grid position

BoardTarget TestBoard() { return {7, 5, 8.0, 6.0, "DICT_5X5_100"}; }

// Detects the board in a rectified image and compares the corners with where the grid says they
// are: returns the scale (detected / expected spacing) and the RMS position error in grid pixels.
void MeasureGrid(const Image& rectified, const MetricGrid& grid, double* scale, double* rms_px) {
  const BoardObservation observation = DetectBoard(rectified, TestBoard(), "rectified");
  const auto corners = BoardCornersInWorld(TestBoard());
  std::vector<Eigen::Vector2d> expected, detected;
  for (std::size_t i = 0; i < observation.corner_ids.size(); ++i) {
    const Eigen::Vector3d& p = corners[observation.corner_ids[i]];
    expected.emplace_back((p.x() - grid.x0_mm) / grid.pitch_mm - 0.5, (grid.y1_mm - p.y()) / grid.pitch_mm - 0.5);
    detected.push_back(observation.pixels[i]);
  }
  Eigen::Vector2d mean_e = Eigen::Vector2d::Zero(), mean_d = Eigen::Vector2d::Zero();
  for (std::size_t i = 0; i < expected.size(); ++i) mean_e += expected[i], mean_d += detected[i];
  mean_e /= expected.size(), mean_d /= detected.size();
  double num = 0, den = 0, sq = 0;
  for (std::size_t i = 0; i < expected.size(); ++i) {
    num += (detected[i] - mean_d).dot(expected[i] - mean_e);
    den += (expected[i] - mean_e).squaredNorm();
    sq += (detected[i] - expected[i]).squaredNorm();
  }
  *scale = num / den;
  *rms_px = std::sqrt(sq / expected.size());
}

TEST(Rectification, ObliqueCameraWithDistortionMapsAtTheTrueDpi) {
  CameraModel camera = testing::TiltedCamera(480, 360, 260.0, 90.0, 35.0, 10.0);
  camera.distortion = {-0.12, 0.04, 0.001, -0.0005, 0.0};
  const Image frame = testing::RenderBoard(camera, TestBoard());
  OutputSpec output;
  output.dpi = 250.0;
  output.region_mm = std::array<double, 4>{-32.0, -24.0, 32.0, 24.0};
  const MetricGrid grid = ChooseGrid({camera}, output);
  EXPECT_NEAR(grid.dpi(), 250.0, 1e-9);
  for (bool pose_from_board : {false, true}) {
    CameraModel used = camera;
    if (pose_from_board) {
      CameraModel unposed = camera;
      unposed.pose = CameraPose{};
      used.pose = EstimateBoardPose(unposed, TestBoard(), DetectBoard(frame, TestBoard(), "board.tif")).pose;
    }
    const RectificationMap map = BuildRectificationMap(used, grid);
    EXPECT_FALSE(map.crop_and_scale);
    const RectifiedFrame rectified = Rectify({frame, {}}, map);
    EXPECT_EQ(rectified.rgb.width(), grid.width);
    EXPECT_DOUBLE_EQ(rectified.rgb.pitch_mm(), grid.pitch_mm);
    double scale = 0, rms = 0;
    MeasureGrid(rectified.rgb, grid, &scale, &rms);
    std::cout << "measured: oblique camera, pose " << (pose_from_board ? "from the board" : "known")
              << ": map scale error " << std::abs(scale - 1.0) * 100.0 << " %, corner RMS " << rms << " grid px\n";
    EXPECT_LT(std::abs(scale - 1.0), kMaxScaleError);
    EXPECT_LT(rms, kMaxRegistrationErrorPx);
  }
}

TEST(Rectification, StraightDownCameraIsACropAndAScale) {
  const CameraModel camera = testing::DownCamera(400, 300, 300.0, 70.0);
  const MetricGrid grid = ChooseGrid({camera}, OutputSpec{});
  // Native resolution, rounded down to a whole dpi; the region inside the 70 x 52.5 mm view.
  EXPECT_NEAR(grid.dpi(), std::floor(25.4 / (70.0 / 400.0)), 1e-9);
  EXPECT_GE(grid.x0_mm, -35.0);
  EXPECT_LE(grid.x0_mm + grid.width * grid.pitch_mm, 35.0 + 1e-9);
  EXPECT_GT(grid.width * grid.pitch_mm, 69.0);
  const RectificationMap map = BuildRectificationMap(camera, grid);
  EXPECT_TRUE(map.crop_and_scale);
  EXPECT_EQ(std::count(map.out_of_view.begin(), map.out_of_view.end(), 1), 0);
  double scale = 0, rms = 0;
  MeasureGrid(Rectify({testing::RenderBoard(camera, TestBoard()), {}}, map).rgb, grid, &scale, &rms);
  std::cout << "measured: straight-down camera: map scale error " << std::abs(scale - 1.0) * 100.0 << " %, corner RMS "
            << rms << " grid px\n";
  EXPECT_LT(std::abs(scale - 1.0), kMaxScaleError);
  EXPECT_LT(rms, kMaxRegistrationErrorPx);
}

TEST(Rectification, OutOfViewAndSaturatedPixelsAreFlagged) {
  const CameraModel camera = testing::DownCamera(64, 48, 300.0, 64.0);  // 1 mm per pixel
  OutputSpec output;
  output.dpi = 25.4;  // 1 mm grid
  output.region_mm = std::array<double, 4>{-40.0, -20.0, 40.0, 20.0};  // wider than the view
  const MetricGrid grid = ChooseGrid({camera}, output);
  const RectificationMap map = BuildRectificationMap(camera, grid);
  DecodedFrame frame{Image(64, 48, 3, 0.5f), std::vector<std::uint8_t>(64 * 48, 0)};
  frame.saturated[20 * 64 + 32] = 1;
  const RectifiedFrame rectified = Rectify(frame, map);
  EXPECT_TRUE(rectified.flags[10 * grid.width + 0] & kOutOfView);    // x = -39.5 mm: outside
  EXPECT_FALSE(rectified.flags[10 * grid.width + 40] & kOutOfView);  // x = 0.5 mm: inside
  int saturated = 0;
  for (auto f : rectified.flags) saturated += (f & kSaturated) ? 1 : 0;
  // One saturated camera pixel taints the grid pixels whose kernel reaches it: a 2x2 footprint
  // for bilinear, 4x4 for bicubic, 8x8 for Lanczos-4 (1 mm grid = 1 camera pixel here).
  constexpr int kKernelSide = kDefaultRectifyInterpolation == RectifyInterpolation::kLinear  ? 2
                              : kDefaultRectifyInterpolation == RectifyInterpolation::kCubic ? 4
                                                                                             : 8;
  EXPECT_GE(saturated, 1);
  EXPECT_LE(saturated, kKernelSide * kKernelSide);
  EXPECT_NEAR(rectified.rgb.at(1, 10, 40), 0.5f, 1e-5f);
}

TEST(Rectification, FootprintPrefilterKernelIsANormalisedSymmetricBox) {
  for (double s : {0.5, 1.0}) {
    EXPECT_EQ(FootprintPrefilterKernel(s), std::vector<float>{1.0f}) << "s = " << s;
    EXPECT_EQ(FootprintPrefilterReach(s), 0);
  }
  for (double s : {1.05, 1.5, 2.0, 3.0, 4.5}) {
    const std::vector<float> taps = FootprintPrefilterKernel(s);
    const int reach = FootprintPrefilterReach(s);
    ASSERT_EQ(taps.size(), static_cast<std::size_t>(2 * reach + 1)) << "s = " << s;
    double sum = 0.0;
    for (int q = -reach; q <= reach; ++q) {
      sum += taps[q + reach];
      EXPECT_GT(taps[q + reach], 0.0f) << "s = " << s << ", tap " << q;
      EXPECT_FLOAT_EQ(taps[q + reach], taps[reach - q]) << "s = " << s;
    }
    EXPECT_NEAR(sum, 1.0, 1e-6) << "s = " << s;
    // The box is sqrt(s^2 - 1) wide over the linear interpolation: it reaches 1 + w/2 pixels.
    EXPECT_EQ(reach, static_cast<int>(std::ceil(1.0 + 0.5 * std::sqrt(s * s - 1.0))) - 1) << "s = " << s;
  }
}

// Each finished map pixel must hold the fabric averaged over its footprint. A straight-down camera
// (no distortion) sees cos patterns along x and y whose every camera pixel is the exact average over
// that pixel; on a grid s times coarser and a fraction of a pixel off the camera's, the rectified
// value is compared with the exact average over each grid pixel. Period 3 grid pixels: threads
// 1.5 grid pixels wide, near the grid's Nyquist limit, where resampling matters most.
TEST(Rectification, CoarseGridHoldsTheFootprintAverage) {
  // Bound on the RMS error over the interior, relative to the pattern's amplitude, per s. Measured
  // 0.059 / 0.034 / 0.013 at s = 1.5 / 2 / 3; the Gaussian pre-filter at the grid's Nyquist limit
  // that this replaced (none below s = 1.5) left 0.064 / 0.092 / 0.111. At 1.5 the bicubic
  // interpolation's own error dominates.
  const std::vector<std::pair<double, double>> kMaxRelativeRmsError = {{1.5, 0.07}, {2.0, 0.045}, {3.0, 0.02}};
  constexpr double kCameraPitchMm = 0.1, kAmplitude = 0.3, kMean = 0.5, kPeriodGridPx = 3.0;
  const CameraModel camera = testing::DownCamera(240, 240, 300.0, 240 * kCameraPitchMm);
  for (const auto& [s, max_error] : kMaxRelativeRmsError) {
    const double grid_pitch = s * kCameraPitchMm;
    OutputSpec output;
    output.dpi = 25.4 / grid_pitch;
    output.region_mm = std::array<double, 4>{-9.037, -9.013, 9.0, 9.0};  // off the camera's pixel lattice
    const MetricGrid grid = ChooseGrid({camera}, output);
    const double k = 2.0 * M_PI / (kPeriodGridPx * grid_pitch);
    // Mean of cos(k t) over [t - a/2, t + a/2] = cos(k t) sinc(k a / 2).
    auto box_mean = [&](double t, double a) { return std::cos(k * t) * std::sin(0.5 * k * a) / (0.5 * k * a); };
    Image frame(camera.width, camera.height, 1, 0.0f);
    for (int v = 0; v < camera.height; ++v) {
      for (int u = 0; u < camera.width; ++u) {
        Eigen::Vector3d p;
        ASSERT_TRUE(camera.PixelToPlane({u, v}, 0.0, &p));
        frame.at(0, v, u) = static_cast<float>(kMean + 0.5 * kAmplitude * (box_mean(p.x(), kCameraPitchMm) + box_mean(p.y(), kCameraPitchMm)));
      }
    }
    const RectificationMap map = BuildRectificationMap(camera, grid);
    const Image rectified = RectifyImage(frame, map);
    double sq = 0.0;
    int count = 0;
    constexpr int kBorder = 4;
    for (int row = kBorder; row < grid.height - kBorder; ++row) {
      for (int col = kBorder; col < grid.width - kBorder; ++col) {
        const Eigen::Vector3d c = grid.PixelCentreInWorld(col, row);
        const double truth = kMean + 0.5 * kAmplitude * (box_mean(c.x(), grid_pitch) + box_mean(c.y(), grid_pitch));
        sq += std::pow(rectified.at(0, row, col) - truth, 2);
        ++count;
      }
    }
    const double relative = std::sqrt(sq / count) / kAmplitude;
    std::cout << "measured: grid " << s << "x coarser than the camera, period 3 grid px: RMS error " << relative
              << " of the amplitude\n";
    EXPECT_LT(relative, max_error) << "s = " << s;
  }
}

}  // namespace
}  // namespace u3mscan
