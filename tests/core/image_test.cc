#include "core/image.h"

#include <gtest/gtest.h>

#include "core/stack.h"

namespace u3mscan {
namespace {

TEST(Image, PlanarLayoutAndAccess) {
  Image image(4, 3, 2, 0.0f, 0.1);
  image.at(1, 2, 3) = 7.0f;
  EXPECT_EQ(image.pixel_count(), 12u);
  EXPECT_EQ(image.plane(1)[2 * 4 + 3], 7.0f);
  EXPECT_EQ(image.plane(0)[2 * 4 + 3], 0.0f);
  EXPECT_DOUBLE_EQ(image.pitch_mm(), 0.1);
  EXPECT_NEAR(image.ChannelMean(1), 7.0 / 12.0, 1e-12);
}

TEST(Image, RejectsNegativeAndOverflowingSizes) {
  EXPECT_THROW(Image(-1, 3, 1), std::invalid_argument);
  EXPECT_THROW(Image(1 << 30, 1 << 30, 1 << 30), std::length_error);
}

TEST(MetricGrid, PixelCentresFollowTheContract) {
  MetricGrid grid{10, 5, 0.2, 1.0, 3.0};
  const Eigen::Vector3d top_left = grid.PixelCentreInWorld(0, 0);
  EXPECT_DOUBLE_EQ(top_left.x(), 1.1);
  EXPECT_DOUBLE_EQ(top_left.y(), 2.9);
  const Eigen::Vector3d below = grid.PixelCentreInWorld(0, 1);
  EXPECT_LT(below.y(), top_left.y()) << "rows grow with -y";
  EXPECT_NEAR(grid.dpi(), 127.0, 1e-9);
}

TEST(LightModel, PointLightFallsOffWithInverseSquareAndProfile) {
  LightModel light;
  light.type = LightType::kPoint;
  light.position_in_world_mm = {0, 0, 100};
  const Eigen::Vector3d origin(0, 0, 0);
  EXPECT_NEAR(light.RelativeIrradianceAt(origin), 1e-4, 1e-15);
  EXPECT_NEAR(light.DirectionFrom(origin).z(), 1.0, 1e-15);
  light.has_profile = true;
  light.profile_axis_in_world = {0, 0, -1};
  light.profile_exponent = 2.0;
  const Eigen::Vector3d off_axis(100, 0, 0);  // 45 deg off the emitter axis, d^2 = 2e4
  EXPECT_NEAR(light.RelativeIrradianceAt(off_axis), 0.5 / 2e4, 1e-15);
}

}  // namespace
}  // namespace u3mscan
