#include "capture/flat_field.h"

#include <gtest/gtest.h>

#include <iostream>

#include "capture/rectification.h"
#include "core/error.h"
#include "core/units.h"
#include "synthetic_views.h"

namespace u3mscan {
namespace {

constexpr double kMaxNonUniformity = 0.01;  // issue 4: flat-fielded white target uniform within 1 %
constexpr double kFlatReflectance = 0.9;
constexpr double kTargetReflectance = 0.5;

LightModel NearLight() {
  LightModel light;
  light.id = "L1";
  light.type = LightType::kPoint;
  light.position_in_world_mm = Eigen::Vector3d(60.0, 40.0, 150.0);
  light.intensity_rgb = Eigen::Vector3d(1.0, 0.9, 0.8) * 2e4;
  light.has_profile = true;
  light.profile_axis_in_world = (Eigen::Vector3d(0, 0, 0) - light.position_in_world_mm).normalized();
  light.profile_exponent = 2.0;
  return light;
}

// A Lambertian plane of reflectance rho under `light`, read by `camera` with lens vignetting
// 1 - vignetting * r^2 (r: distance from the image centre over the half-diagonal).
Image RenderLambertian(const CameraModel& camera, const LightModel& light, double rho, double exposure_s,
                       double vignetting) {
  Image image(camera.width, camera.height, 3);
  const double half_diagonal = 0.5 * std::hypot(camera.width, camera.height);
  for (int row = 0; row < camera.height; ++row) {
    for (int col = 0; col < camera.width; ++col) {
      Eigen::Vector3d p;
      if (!camera.PixelToPlane({col, row}, 0.0, &p)) continue;
      const double r = std::hypot(col - camera.intrinsics.cx, row - camera.intrinsics.cy) / half_diagonal;
      const double cos_theta = std::max(0.0, light.DirectionFrom(p).z());
      for (int c = 0; c < 3; ++c) {
        image.at(c, row, col) = static_cast<float>(exposure_s * rho / kPi * cos_theta * light.intensity_rgb[c] *
                                                   light.RelativeIrradianceAt(p) * (1.0 - vignetting * r * r));
      }
    }
  }
  return image;
}

// Reflectance estimated from a rectified sample frame with the given irradiance: one channel.
Image Albedo(const Image& sample_on_grid, double exposure_s, const LightModel& light, const MetricGrid& grid,
             const Image& irradiance) {
  Image albedo(grid.width, grid.height, 1);
  for (int row = 0; row < grid.height; ++row) {
    for (int col = 0; col < grid.width; ++col) {
      const double cos_theta = light.DirectionFrom(grid.PixelCentreInWorld(col, row)).z();
      const double e = irradiance.at(0, row, col);
      albedo.at(0, row, col) = static_cast<float>(
          kPi * sample_on_grid.at(1, row, col) / (exposure_s * light.intensity_rgb[1]) / (cos_theta * e));
    }
  }
  return albedo;
}

struct FlatRig {
  CameraModel camera = testing::DownCamera(96, 72, 300.0, 96.0);
  LightModel light = NearLight();
  MetricGrid grid;
  RectificationMap map;
  FlatRig() {
    OutputSpec output;
    output.dpi = 25.4;
    output.region_mm = std::array<double, 4>{-40.0, -30.0, 40.0, 30.0};
    grid = ChooseGrid({camera}, output);
    map = BuildRectificationMap(camera, grid);
  }
};

TEST(FlatField, MeasuredFlatMakesTheWhiteTargetUniform) {
  FlatRig s;
  constexpr double kVignetting = 0.25;
  const FrameSpec flat_spec{"flat_L1.tif", "top", "L1", "front", 0.01, FrameRole::kFlat};
  const Image flat = RectifyImage(RenderLambertian(s.camera, s.light, kFlatReflectance, 0.01, kVignetting), s.map);
  const Image irradiance = MeasuredIrradiance(flat, flat_spec, s.light, s.grid, kFlatReflectance);
  const Image sample = RectifyImage(RenderLambertian(s.camera, s.light, kTargetReflectance, 0.02, kVignetting), s.map);
  const Image albedo = Albedo(sample, 0.02, s.light, s.grid, irradiance);
  std::cout << "measured: flat-fielded white target non-uniformity " << NonUniformity(albedo) * 100.0
            << " %, mean reflectance " << albedo.ChannelMean(0) << "\n";
  EXPECT_LT(NonUniformity(albedo), kMaxNonUniformity);
  EXPECT_NEAR(albedo.ChannelMean(0), kTargetReflectance, 0.005);
  // Without the flat, the analytic model cannot know the vignetting: the test can fail.
  const Image analytic = Albedo(sample, 0.02, s.light, s.grid, AnalyticIrradiance(s.light, s.grid));
  EXPECT_GT(NonUniformity(analytic), 5.0 * kMaxNonUniformity);
}

TEST(FlatField, AnalyticModelIsExactWithoutVignetting) {
  FlatRig s;
  const Image sample = RectifyImage(RenderLambertian(s.camera, s.light, kTargetReflectance, 0.02, 0.0), s.map);
  const Image albedo = Albedo(sample, 0.02, s.light, s.grid, AnalyticIrradiance(s.light, s.grid));
  EXPECT_LT(NonUniformity(albedo), kMaxNonUniformity);
}

TEST(FlatField, FlatDarkerThanSampleNamesTheFlatFrame) {
  FlatRig s;
  const Image fabric = RenderLambertian(s.camera, s.light, 0.6, 0.01, 0.0);
  const Image dim_flat = RenderLambertian(s.camera, s.light, 0.2, 0.01, 0.0);
  const FrameSpec flat_spec{"calibration/flat_L1.tif", "top", "L1", "front", 0.01, FrameRole::kFlat};
  const FrameSpec sample_spec{"frames/L1.tif", "top", "L1", "front", 0.01, FrameRole::kSample};
  EXPECT_NO_THROW(CheckFlatBrighterThanSample(fabric, flat_spec, 3, dim_flat, sample_spec));
  try {
    CheckFlatBrighterThanSample(dim_flat, flat_spec, 3, fabric, sample_spec);
    FAIL() << "expected InputError";
  } catch (const InputError& error) {
    EXPECT_EQ(error.file(), "calibration/flat_L1.tif");
    EXPECT_EQ(error.field(), "/frames/3");
    EXPECT_NE(std::string(error.what()).find("frames/L1.tif"), std::string::npos) << error.what();
  }
}

}  // namespace
}  // namespace u3mscan
