#include "capture/colour_calibration.h"

#include <gtest/gtest.h>

#include <iostream>
#include <random>

#include "core/error.h"
#include "core/units.h"
#include "synthetic_views.h"

namespace u3mscan {
namespace {

constexpr double kMaxMeanDeltaEAfter = 1.5;  // issue 4: CIEDE2000 mean after correction
constexpr double kCosTheta = 0.8;            // the directional light's cosine on the chart
constexpr double kNoise = 0.003;             // relative per-pixel noise

// The camera's own RGB: cross-talk between channels and a grey-world gain error.
Eigen::Matrix3d CameraFromSrgb() {
  Eigen::Matrix3d m;
  m << 0.78, 0.17, 0.05, 0.12, 0.80, 0.08, 0.04, 0.22, 0.74;
  return m * Eigen::Vector3d(1.1, 1.0, 0.85).asDiagonal();
}

Image RenderChart(const CameraModel& camera, const ChartLayout& layout) {
  const auto& reference = ClassicChartLinearSrgb();
  const Eigen::Matrix3d to_camera = CameraFromSrgb();
  Image image = testing::RenderPlane(camera, [&](const Eigen::Vector3d& p) -> Eigen::Vector3d {
    const double u = (p.x() - layout.centre_mm.x()) / layout.patch_pitch_mm + 3.0;
    const double v = 2.0 - (p.y() - layout.centre_mm.y()) / layout.patch_pitch_mm;
    Eigen::Vector3d rho = Eigen::Vector3d::Constant(0.25);  // grey table
    if (u >= -0.3 && u < 6.3 && v >= -0.3 && v < 4.3) rho = Eigen::Vector3d::Constant(0.03);  // black frame
    const int col = static_cast<int>(std::floor(u)), row = static_cast<int>(std::floor(v));
    if (col >= 0 && col < 6 && row >= 0 && row < 4 && u - col > 0.08 && u - col < 0.92 && v - row > 0.08 &&
        v - row < 0.92) {
      const Rgb& r = reference[row * 6 + col];
      rho = Eigen::Vector3d(r[0], r[1], r[2]);
    }
    // A mild per-channel curve stands in for the spectral mismatch no 3x3 matrix can undo.
    const Eigen::Vector3d camera_rho = (to_camera * rho).array().max(0.0).pow(1.04).matrix();
    return camera_rho * kCosTheta / kPi;  // exposure 1 s, intensity 1
  }, 2);
  std::mt19937 rng(7);
  std::normal_distribution<float> noise(0.0f, 1.0f);
  for (float& v : image.data()) v *= 1.0f + static_cast<float>(kNoise) * noise(rng);
  return image;
}

std::vector<Rgb> ToReflectance(const std::vector<ChartPatch>& patches) {
  std::vector<Rgb> out;
  for (const auto& p : patches) {
    out.push_back({p.mean_rgb[0] * kPi / kCosTheta, p.mean_rgb[1] * kPi / kCosTheta, p.mean_rgb[2] * kPi / kCosTheta});
  }
  return out;
}

TEST(ColourCalibration, ChartAtKnownLayoutCorrectsToBelowOnePointFiveDeltaE) {
  const CameraModel camera = testing::DownCamera(360, 270, 300.0, 90.0);
  const ChartLayout layout{Eigen::Vector2d(2.0, -1.0), 12.0};
  const Image frame = RenderChart(camera, layout);
  const auto patches = MeasureChartAtLayout(frame, camera, layout, "chart.tif");
  ASSERT_EQ(patches.size(), 24u);
  const auto& reference = ClassicChartLinearSrgb();
  const ColourFit fit = FitColourCorrection(ToReflectance(patches), {reference.begin(), reference.end()});
  std::cout << "measured: colour chart CIEDE2000 mean " << fit.delta_e_before_mean << " before, "
            << fit.delta_e_after_mean << " after (max " << fit.delta_e_after_max << ")\n";
  EXPECT_LT(fit.delta_e_after_mean, kMaxMeanDeltaEAfter);
  EXPECT_GT(fit.delta_e_before_mean, 3.0 * fit.delta_e_after_mean);
  // The fit undoes the camera's mixing.
  EXPECT_LT((fit.matrix * CameraFromSrgb() - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff(), 0.1);
}

TEST(ColourCalibration, MccDetectorOrLayoutFindsTheSameChart) {
  // mcc is tried first in calibration; when it finds the rendered chart its patches must agree
  // with the known layout's.
  const CameraModel camera = testing::DownCamera(360, 270, 300.0, 90.0);
  const ChartLayout layout{Eigen::Vector2d(0.0, 0.0), 12.0};
  const Image frame = RenderChart(camera, layout);
  const auto by_layout = MeasureChartAtLayout(frame, camera, layout, "chart.tif");
  const auto by_mcc = MeasureChartWithMcc(frame);
  std::cout << "measured: mcc " << (by_mcc ? "found" : "did not find") << " the rendered chart\n";
  if (by_mcc) {
    // mcc's box is good to a fraction of a patch; the sampled centre half stays inside the patch
    // as long as the centres agree within 0.15 of the pitch (48 px here).
    constexpr double kPatchPitchPx = 12.0 / (90.0 / 360.0);
    ASSERT_EQ(by_mcc->size(), 24u);
    for (int i = 0; i < 24; ++i) {
      EXPECT_LT(((*by_mcc)[i].centre_px - by_layout[i].centre_px).norm(), 0.15 * kPatchPitchPx) << "patch " << i + 1;
    }
    const auto& reference = ClassicChartLinearSrgb();
    const ColourFit fit = FitColourCorrection(ToReflectance(*by_mcc), {reference.begin(), reference.end()});
    std::cout << "measured: chart found by mcc: CIEDE2000 mean " << fit.delta_e_after_mean << " after\n";
    EXPECT_LT(fit.delta_e_after_mean, kMaxMeanDeltaEAfter);
  }
}

TEST(ColourCalibration, UnknownPitchIsFoundFromTheColours) {
  const CameraModel camera = testing::DownCamera(360, 270, 300.0, 90.0);
  const ChartLayout layout{Eigen::Vector2d(0.0, 0.0), 11.0};
  const Image frame = RenderChart(camera, layout);
  const double pitch = FindChartPitchMm(frame, camera, layout.centre_mm);
  std::cout << "measured: chart pitch searched " << pitch << " mm (truth 11 mm)\n";
  EXPECT_NEAR(pitch, 11.0, 0.02 * 11.0);
  const auto& reference = ClassicChartLinearSrgb();
  const ColourFit fit = FitColourCorrection(ToReflectance(MeasureChartAtLayout(frame, camera, {layout.centre_mm, pitch}, "c")),
                                            {reference.begin(), reference.end()});
  EXPECT_LT(fit.delta_e_after_mean, kMaxMeanDeltaEAfter);
}

TEST(ColourCalibration, ChartOutsideTheViewNamesTheFrame) {
  const CameraModel camera = testing::DownCamera(160, 120, 300.0, 40.0);
  const ChartLayout layout{Eigen::Vector2d(0.0, 0.0), 12.0};  // 72 mm wide: larger than the view
  try {
    MeasureChartAtLayout(Image(160, 120, 3, 0.2f), camera, layout, "calibration/chart.tif");
    FAIL() << "expected InputError";
  } catch (const InputError& error) {
    EXPECT_EQ(error.file(), "calibration/chart.tif");
    EXPECT_NE(std::string(error.what()).find("colour chart"), std::string::npos);
  }
}

}  // namespace
}  // namespace u3mscan
