// Point lights from ONE mirror-sphere placement plus the white target on the known sample plane
// (issue 4, light_from_plane.h): the synthetic scanner's near rig (its lens, vignetting, emitter
// profiles and sphere renderer), frames made in memory, the manifest's positions 15 mm off and no
// prior, so the distance along each sphere's ray can only come from the flat frames.
#include "capture/light_from_plane.h"

#include <gtest/gtest.h>

#include <iostream>
#include <map>
#include <random>

#include "capture/calibrate.h"
#include "capture/camera_model.h"
#include "datasets_synthetic/calibration_frames.h"
#include "datasets_synthetic/rig.h"
#include "in_memory_capture.h"

namespace u3mscan {
namespace {

constexpr double kMaxPositionErrorRelative = 0.01;  // issue 4: within 1 % of the light's distance
constexpr double kManifestErrorMm = 15.0;           // a design value 15 mm off (as SyntheticCapture)
// Per-pixel noise of the frames, relative: shot noise of the near rig's sensor at the flat's level
// (0.5 of full scale, 20000 e at full scale: sqrt(10000) / 10000 = 1 %).
constexpr double kFrameNoiseRelative = 0.01;

struct OneSphereCapture : testing::InMemoryCapture {
  synthetic::Rig rig;

  // Lights `keep` of the near rig (both rings), one sphere placement near the view's centre.
  explicit OneSphereCapture(const std::vector<int>& keep, bool with_flats = true) {
    rig = synthetic::MakeRig("near", {320, 240, 0.25, 5});
    std::vector<synthetic::RigLight> lights;
    for (int k : keep) lights.push_back(rig.lights.at(k));
    rig.lights = lights;
    synthetic::CalibrationTargets targets = synthetic::MakeCalibrationTargets(rig);
    targets.sphere_centers_mm = {Eigen::Vector3d(4.0, -3.0, targets.sphere_radius_mm)};
    const synthetic::RigCamera& rc = rig.cameras[0];
    CameraSpec camera;
    camera.id = rc.id;
    camera.width = rc.width;
    camera.height = rc.height;
    camera.intrinsics = {rc.fx, rc.fy, rc.cx, rc.cy};
    camera.distortion = rc.distortion;
    camera.pose = CameraPose{rc.world_from_camera, rc.position_mm};
    manifest.cameras.push_back(camera);
    manifest.targets.white = WhiteTarget{targets.white_reflectance};
    manifest.targets.sphere = SphereTarget{targets.sphere_radius_mm, targets.sphere_centers_mm[0]};
    std::mt19937 random(7);
    std::normal_distribution<float> noise(0.0f, static_cast<float>(kFrameNoiseRelative));
    auto noisy = [&](Image image) {
      for (float& v : image.data()) v *= 1.0f + noise(random);
      return image;
    };
    for (std::size_t l = 0; l < rig.lights.size(); ++l) {
      const synthetic::RigLight& rl = rig.lights[l];
      LightSpec light;
      light.id = rl.id;
      light.type = ManifestLightType::kPoint;
      const double a = 2.399 * l;  // golden-angle turns: offsets in every direction
      light.position_mm = rl.position_mm + kManifestErrorMm * Eigen::Vector3d(std::cos(a), std::sin(a), (l % 2) ? 0.5 : -0.5).normalized();
      light.intensity_rgb = rl.intensity_rgb;
      light.profile = LightProfile{rl.profile_axis, rl.profile_exponent};
      manifest.lights.push_back(light);
      const int li = static_cast<int>(l);
      Add({"sphere_" + rl.id + ".exr", rc.id, rl.id, "front", rig.exposure_s, FrameRole::kSphere},
          synthetic::RenderSphereFrame(rig, 0, targets, li, 0));
      if (with_flats) {
        Add({"flat_" + rl.id + ".exr", rc.id, rl.id, "front", rig.exposure_s, FrameRole::kFlat},
            noisy(synthetic::RenderFlatFrame(rig, 0, targets, li)));
      }
    }
  }
};

CalibrationOptions NoPrior() {
  CalibrationOptions options;
  options.light_fit.manifest_position_sigma_mm = 0.0;  // the distance must come from the flats
  return options;
}

const StepReport* FindStep(const CalibrationResult& result, const std::string& name) {
  for (const auto& s : result.steps) {
    if (s.step == name) return &s;
  }
  return nullptr;
}

TEST(LightFromPlane, OneSpherePlacementAndTheFlatsGivePositionsWithinOnePercent) {
  const OneSphereCapture capture({0, 3, 9, 14});
  const CalibrationResult result = Calibrate(capture.manifest, capture.Loader(), NoPrior());
  for (const auto& w : result.warnings) std::cout << "warning: " << w << "\n";
  double worst = 0.0;
  for (const auto& truth : capture.rig.lights) {
    const LightCalibration* found = result.FindLight(truth.id);
    ASSERT_NE(found, nullptr);
    const StepReport* step = FindStep(result, "light " + truth.id + " distance from flat");
    ASSERT_NE(step, nullptr) << truth.id;
    std::cout << (step->ran ? "ran " : "skipped ") << step->step << ": " << step->detail << "\n";
    EXPECT_TRUE(step->ran) << step->detail;
    EXPECT_EQ(found->source, "mirror sphere + flat") << truth.id;
    const double error = (found->model.position_in_world_mm - truth.position_mm).norm() / truth.position_mm.norm();
    const double manifest_error =
        (*capture.manifest.FindLight(truth.id)->position_mm - truth.position_mm).norm() / truth.position_mm.norm();
    std::cout << "measured: one placement + flat, light " << truth.id << " position error " << error * 100.0
              << " % of " << truth.position_mm.norm() << " mm (manifest " << manifest_error * 100.0 << " %)\n";
    EXPECT_LT(error, kMaxPositionErrorRelative) << truth.id;
    worst = std::max(worst, error);
  }
  std::cout << "measured: one sphere placement + flat frames, near rig, worst position error " << worst * 100.0
            << " %\n";
}

TEST(LightFromPlane, WithoutFlatsTheManifestDistanceIsKeptAndTheLogSaysWhy) {
  const OneSphereCapture capture({0, 9}, false);
  const CalibrationResult result = Calibrate(capture.manifest, capture.Loader(), NoPrior());
  for (const auto& truth : capture.rig.lights) {
    const StepReport* step = FindStep(result, "light " + truth.id + " distance from flat");
    ASSERT_NE(step, nullptr) << truth.id;
    EXPECT_FALSE(step->ran);
    EXPECT_NE(step->detail.find("no flat frame"), std::string::npos) << step->detail;
    EXPECT_EQ(result.FindLight(truth.id)->source, "mirror sphere");
  }
}

TEST(LightFromPlane, UnknownProfileFitsTheExponentOrSaysItCannot) {
  // The manifest gives no emitter profile: the exponent is fitted with the distance (axis toward
  // the target's centre). Either the light lands within 1 % or the fit is refused with a reason
  // naming the flat frame and the light keeps the sphere's (manifest) distance.
  OneSphereCapture capture({0, 9});
  for (auto& light : capture.manifest.lights) light.profile.reset();
  const CalibrationResult result = Calibrate(capture.manifest, capture.Loader(), NoPrior());
  for (const auto& truth : capture.rig.lights) {
    const StepReport* step = FindStep(result, "light " + truth.id + " distance from flat");
    ASSERT_NE(step, nullptr);
    std::cout << (step->ran ? "ran " : "skipped ") << step->step << ": " << step->detail << "\n";
    const LightCalibration* found = result.FindLight(truth.id);
    const double error = (found->model.position_in_world_mm - truth.position_mm).norm() / truth.position_mm.norm();
    std::cout << "measured: unknown profile, light " << truth.id << " position error " << error * 100.0
              << " %, exponent " << found->model.profile_exponent << " (truth " << truth.profile_exponent << ")\n";
    if (step->ran) {
      EXPECT_LT(error, kMaxPositionErrorRelative) << truth.id;
    } else {
      EXPECT_NE(step->detail.find("flat_" + truth.id), std::string::npos) << step->detail;
      EXPECT_EQ(found->source, "mirror sphere");
    }
  }
}

TEST(LightFromPlane, ASmallPatchOfTargetIsIllConditionedAndRefusedNamingTheFrame) {
  // 4 x 4 mm of target seen from 400 mm: the shading barely changes with the distance. The fit
  // must say so (sigma above PlaneLightFitOptions::max_relative_sigma) and keep the start model;
  // the whole view fixes the same light to well within it.
  const OneSphereCapture capture({0});
  const synthetic::RigLight& truth = capture.rig.lights[0];
  const CameraModel camera = CameraModel::FromSpec(capture.manifest.cameras[0]);
  const Eigen::Vector3d origin(0.0, 0.0, 7.0);
  const Eigen::Vector3d ray = (truth.position_mm - origin).normalized();
  LightModel start = LightModelFromSpec(capture.manifest.lights[0]);
  start.position_in_world_mm = origin + 1.04 * (truth.position_mm - origin).norm() * ray;  // 4 % too far
  const Image& flat = capture.frames.at(1);  // frames: sphere_L00, flat_L00
  ASSERT_EQ(capture.manifest.frames[1].file, "flat_L00.exr");
  const PlaneLightFit small = FitPointLightOnPlane(flat, {}, camera, start, origin, ray, {-2, -2, 2, 2}, "flat_L00.exr");
  std::cout << "measured: 4 x 4 mm of target: ok " << small.ok << ", 1-sigma " << small.sigma_mm << " mm; "
            << small.reason << "\n";
  EXPECT_FALSE(small.ok);
  EXPECT_NE(small.reason.find("flat_L00.exr"), std::string::npos) << small.reason;
  EXPECT_EQ(small.model.position_in_world_mm, start.position_in_world_mm);
  const PlaneLightFit whole = FitPointLightOnPlane(flat, {}, camera, start, origin, ray, {-38, -28, 38, 28}, "flat_L00.exr");
  std::cout << "measured: the whole view: 1-sigma " << whole.sigma_mm << " mm, position error "
            << (whole.model.position_in_world_mm - truth.position_mm).norm() << " mm\n";
  EXPECT_TRUE(whole.ok) << whole.reason;
  EXPECT_LT((whole.model.position_in_world_mm - truth.position_mm).norm(), kMaxPositionErrorRelative * truth.position_mm.norm());
}

TEST(LightFromPlane, AnOffCentreFalloffReadsAsDistance) {
  // The documented limit (docs/calibration.md, "One placement plus the plane"): the vignetting
  // model is even about the principal point, so a flat with a 1 % gradient across the view's width
  // (an off-centre lens falloff, a tilted target) moves the distance by about 2 %. This test keeps
  // the doc honest: if the model learns such a gradient, the bias falls and the doc must change.
  constexpr double kGradientAcrossWidth = 0.01;
  constexpr double kMinBiasRelative = 0.01;  // the bias the doc reports is ~2 %: well above 1 %
  const OneSphereCapture capture({0, 9});
  const CameraModel camera = CameraModel::FromSpec(capture.manifest.cameras[0]);
  for (std::size_t l = 0; l < capture.rig.lights.size(); ++l) {
    const synthetic::RigLight& truth = capture.rig.lights[l];
    Image flat = capture.frames.at(2 * l + 1);  // frames: sphere_Lxx, flat_Lxx per light
    ASSERT_EQ(capture.manifest.frames[2 * l + 1].file, "flat_" + truth.id + ".exr");
    for (int c = 0; c < 3; ++c) {
      for (int row = 0; row < flat.height(); ++row) {
        for (int col = 0; col < flat.width(); ++col) {
          flat.at(c, row, col) *= static_cast<float>(1.0 + kGradientAcrossWidth * (col - 0.5 * flat.width()) / flat.width());
        }
      }
    }
    const Eigen::Vector3d origin(0.0, 0.0, 7.0);
    const Eigen::Vector3d ray = (truth.position_mm - origin).normalized();
    LightModel start = LightModelFromSpec(capture.manifest.lights[l]);
    start.position_in_world_mm = origin + 1.03 * (truth.position_mm - origin).norm() * ray;
    const PlaneLightFit fit = FitPointLightOnPlane(flat, {}, camera, start, origin, ray, {-38, -28, 38, 28}, "flat");
    const double bias = fit.distance_mm / (truth.position_mm - origin).norm() - 1.0;
    std::cout << "measured: flat with a " << kGradientAcrossWidth * 100.0 << " % gradient across the view, light "
              << truth.id << ": distance off by " << bias * 100.0 << " % (1-sigma " << fit.sigma_mm << " mm)\n";
    EXPECT_GT(std::abs(bias), kMinBiasRelative) << truth.id;
  }
}

}  // namespace
}  // namespace u3mscan
