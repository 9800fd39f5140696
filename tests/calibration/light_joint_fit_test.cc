#include "capture/light_joint_fit.h"

#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <random>

namespace u3mscan {
namespace {

constexpr double kMaxPositionErrorRelative = 0.01;  // issue 4: of the light's distance
constexpr double kRadiusMm = 7.2;                   // the synthetic near rig's sphere
constexpr double kFrameCentreNoiseMm = 0.01;        // a rim fit in one frame (1 sigma per axis; the
                                                    // synthetic near rig's frames: up to 0.011 mm)

// The point of the sphere where a ray from `eye` reflects to `light` (normal = bisector).
Eigen::Vector3d SpecularPoint(const Eigen::Vector3d& eye, const Eigen::Vector3d& light, const Eigen::Vector3d& centre) {
  Eigen::Vector3d p = centre + kRadiusMm * Eigen::Vector3d::UnitZ();
  for (int i = 0; i < 50; ++i) {
    const Eigen::Vector3d n = ((eye - p).normalized() + (light - p).normalized()).normalized();
    p = centre + kRadiusMm * n;
  }
  return p;
}

// What ObserveSphere reports for a highlight seen exactly, on a centre found `centre_error` off.
SphereObservation Observe(const Eigen::Vector3d& eye, const Eigen::Vector3d& light, const Eigen::Vector3d& centre,
                          const Eigen::Vector3d& centre_error) {
  const Eigen::Vector3d dir = (SpecularPoint(eye, light, centre) - eye).normalized();
  SphereObservation o;
  o.radius_mm = kRadiusMm;
  o.centre_in_world_mm = centre + centre_error;
  o.centre_found_in_frame = true;
  o.camera_centre_in_world_mm = eye;
  o.apparent_radius_px = 29.0;
  o.highlight_area_px = 20;
  const Eigen::Vector3d oc = eye - o.centre_in_world_mm;
  const double b = oc.dot(dir);
  const double s = -b - std::sqrt(std::max(0.0, b * b - (oc.squaredNorm() - kRadiusMm * kRadiusMm)));
  o.highlight_point_in_world_mm = eye + s * dir;
  const Eigen::Vector3d n = (o.highlight_point_in_world_mm - o.centre_in_world_mm).normalized();
  o.reflected_in_world = (2.0 * n.dot(-dir) * n + dir).normalized();
  return o;
}

TEST(JointLightFit, SharedPlacementsAverageOutEachFramesCentreError) {
  // The near rig's geometry: camera 300 mm above, three placements ~50 mm apart, 12 point lights
  // ~400 mm away. Every frame finds its sphere's centre with its own error; alone, each light's
  // rays inherit those errors, jointly the placements' centres come from all 12 lights' frames.
  const Eigen::Vector3d eye(0.0, 0.0, 300.0);
  const Eigen::Vector3d centres[] = {{-25.6, -13.2, kRadiusMm}, {25.6, -13.2, kRadiusMm}, {0.0, 16.8, kRadiusMm}};
  std::mt19937 random(7);
  std::normal_distribution<double> noise(0.0, kFrameCentreNoiseMm);
  std::vector<JointLightInput> inputs;
  std::vector<Eigen::Vector3d> truths;
  for (int l = 0; l < 12; ++l) {
    const double azimuth = 2.0 * M_PI * l / 12.0, elevation = (l % 2 ? 30.0 : 55.0) * M_PI / 180.0;
    const Eigen::Vector3d light = 400.0 * Eigen::Vector3d(std::cos(elevation) * std::cos(azimuth),
                                                          std::cos(elevation) * std::sin(azimuth), std::sin(elevation));
    truths.push_back(light);
    JointLightInput input;
    input.start.id = "L";
    input.start.id += std::to_string(l);  // (GCC 12 warns falsely on "L" + to_string)
    input.start.type = LightType::kPoint;
    input.start.position_in_world_mm = light + Eigen::Vector3d(10.0, -8.0, 6.0);  // the manifest, 14 mm off
    for (const auto& c : centres) input.observations.push_back(Observe(eye, light, c, Eigen::Vector3d(noise(random), noise(random), 0.0)));
    inputs.push_back(std::move(input));
  }
  LightFitOptions options;
  options.manifest_position_sigma_mm = 0.0;  // triangulation alone
  const JointLightFit joint = FitLightsJointly(inputs, options);
  ASSERT_EQ(joint.lights.size(), inputs.size());
  EXPECT_EQ(joint.placements, 3);
  double worst_alone = 0.0, worst_joint = 0.0;
  for (std::size_t l = 0; l < inputs.size(); ++l) {
    const LightFit alone = FitPointLight(inputs[l].observations, inputs[l].start, options);
    const double d = truths[l].norm();
    worst_alone = std::max(worst_alone, (alone.model.position_in_world_mm - truths[l]).norm() / d);
    worst_joint = std::max(worst_joint, (joint.lights[l].model.position_in_world_mm - truths[l]).norm() / d);
    EXPECT_EQ(joint.lights[l].residual_unit, "mm");
    EXPECT_NE(joint.lights[l].note.find("joint fit over 3 placement(s)"), std::string::npos);
  }
  for (int p = 0; p < 3; ++p) {
    // Pooled over 12 frames: within two sigmas of a 12-frame mean (2D: sigma * sqrt(2 / 12)).
    const double pooled_tolerance_mm = 2.0 * kFrameCentreNoiseMm * std::sqrt(2.0 / 12.0);
    EXPECT_LT((joint.placement_centres_mm[p] - centres[p]).norm(), pooled_tolerance_mm) << p;
  }
  std::cout << "measured: 12 point lights, 3 placements, frame centres off by " << kFrameCentreNoiseMm
            << " mm: worst position error alone " << worst_alone * 100.0 << " %, jointly " << worst_joint * 100.0 << " %\n";
  EXPECT_GT(worst_alone, kMaxPositionErrorRelative);  // the frames' centre errors alone break the target
  EXPECT_LT(worst_joint, kMaxPositionErrorRelative);
}

TEST(JointLightFit, ManifestCentresStayFixed) {
  const Eigen::Vector3d eye(0.0, 0.0, 300.0), centre(0.0, 0.0, kRadiusMm), light(200.0, 50.0, 300.0);
  JointLightInput input;
  input.start.type = LightType::kPoint;
  input.start.position_in_world_mm = light;
  input.observations.push_back(Observe(eye, light, centre, Eigen::Vector3d::Zero()));
  input.observations.back().centre_found_in_frame = false;
  const JointLightFit joint = FitLightsJointly({input});
  ASSERT_EQ(joint.placement_centres_mm.size(), 1u);
  EXPECT_EQ(joint.placement_centres_mm[0], centre);
  EXPECT_DOUBLE_EQ(joint.centre_shift_rms_mm, 0.0);
}

}  // namespace
}  // namespace u3mscan
