// Point-light calibration on a whole synthetic near-rig capture with all 16 lights, step by step:
// what the highlight locator and the joint fit each contribute. The capture takes ~20 s to render,
// so it is made once by hand and named by an environment variable; without it the test is skipped:
//   u3mscan synth --scene plain --rig near --size 320x240 --format exr --seed 5 --dpi 101.6 -o DIR
//   U3MSCAN_NEAR_RIG_CAPTURE=DIR ./build/tests/calibration/calibration_tests --gtest_filter='NearRigMeasurement.*'
#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <iostream>
#include <map>
#include <nlohmann/json.hpp>

#include "capture/capture.h"
#include "capture/light_calibration.h"
#include "capture/light_joint_fit.h"
#include "core/error.h"

namespace u3mscan {
namespace {

constexpr double kMaxPositionErrorRelative = 0.01;  // issue 4: of the light's distance
constexpr double kManifestErrorMm = 15.0;           // as SyntheticCapture.NearRigPointLightPositions

Eigen::Vector3d Vec(const nlohmann::json& a) { return {a[0].get<double>(), a[1].get<double>(), a[2].get<double>()}; }

TEST(NearRigMeasurement, EveryLightStepByStep) {
  const char* dir = std::getenv("U3MSCAN_NEAR_RIG_CAPTURE");
  if (!dir) GTEST_SKIP() << "U3MSCAN_NEAR_RIG_CAPTURE not set (a near-rig capture made by u3mscan synth, see the file's head)";
  const Capture capture = Capture::Open(std::string(dir) + "/capture");
  const nlohmann::json truth = nlohmann::json::parse(std::ifstream(std::string(dir) + "/truth/truth.json"));
  const Manifest& manifest = capture.manifest();
  ASSERT_TRUE(manifest.targets.sphere);
  const CameraModel camera = CameraModel::FromSpec(manifest.cameras.at(0));
  std::map<std::string, Eigen::Vector3d> lights;
  for (const auto& l : truth["rig"]["lights"]) lights[l["id"].get<std::string>()] = Vec(l["position_mm"]);
  std::vector<Eigen::Vector3d> centres;
  for (const auto& c : truth["rig"]["targets"]["sphere"]["centers_mm"]) centres.push_back(Vec(c));
  const double radius = manifest.targets.sphere->radius_mm;
  // Per light: centre found in the frame (blob / refined highlight), true centre (blob / refined).
  std::map<std::string, std::vector<SphereObservation>> found_blob, found, true_blob, true_refined;
  for (std::size_t i = 0; i < manifest.frames.size(); ++i) {
    const FrameSpec& f = manifest.frames[i];
    if (f.role != FrameRole::kSphere) continue;
    const int placement = f.extra.value("sphere_placement", -1);
    ASSERT_GE(placement, 0) << f.file;
    const DecodedFrame frame = capture.LoadFrame(i);
    try {
      found_blob[*f.light].push_back(ObserveSphere(frame.rgb, camera, *manifest.targets.sphere, f.file, std::nullopt, radius, false));
      found[*f.light].push_back(ObserveSphere(frame.rgb, camera, *manifest.targets.sphere, f.file, std::nullopt, radius));
      true_blob[*f.light].push_back(ObserveSphere(frame.rgb, camera, *manifest.targets.sphere, f.file, centres[placement], {}, false));
      true_refined[*f.light].push_back(ObserveSphere(frame.rgb, camera, *manifest.targets.sphere, f.file, centres[placement]));
    } catch (const InputError& error) {
      std::cout << "skipped: " << error.what() << "\n";  // a highlight hidden from the camera
    }
  }
  LightFitOptions no_prior;
  no_prior.manifest_position_sigma_mm = 0.0;
  auto worst_alone = [&](std::map<std::string, std::vector<SphereObservation>>& per_light) {
    double worst = 0.0;
    for (auto& [id, observations] : per_light) {
      LightModel start;
      start.type = LightType::kPoint;
      start.position_in_world_mm = lights.at(id);
      const LightFit fit = FitPointLight(observations, start, no_prior);
      worst = std::max(worst, (fit.model.position_in_world_mm - lights.at(id)).norm() / lights.at(id).norm());
    }
    return worst;
  };
  auto worst_joint = [&](const LightFitOptions& options, bool manifest_off, double* sigma_scale) {
    std::vector<JointLightInput> inputs;
    int k = 0;
    for (auto& [id, observations] : found) {
      JointLightInput input;
      input.start.id = id;
      input.start.type = LightType::kPoint;
      const double a = 2.399 * k++;
      input.start.position_in_world_mm =
          lights.at(id) + (manifest_off ? kManifestErrorMm : 0.0) *
                              Eigen::Vector3d(std::cos(a), std::sin(a), (k % 2) ? -0.5 : 0.5).normalized();
      input.observations = observations;
      inputs.push_back(std::move(input));
    }
    const JointLightFit joint = FitLightsJointly(inputs, options);
    *sigma_scale = joint.sigma_scale;
    double worst = 0.0;
    for (std::size_t i = 0; i < inputs.size(); ++i) {
      const Eigen::Vector3d& t = lights.at(inputs[i].start.id);
      worst = std::max(worst, (joint.lights[i].model.position_in_world_mm - t).norm() / t.norm());
    }
    return worst;
  };
  LightFitOptions tight_centres = no_prior;
  tight_centres.centre_prior_sigma_of_radius = 0.001;
  LightFitOptions defaults;  // manifest prior 10 mm
  double scale_tight = 1, scale_loose = 1, scale_prior = 1;
  const double alone_blob = worst_alone(found_blob), alone = worst_alone(found);
  const double centres_blob = worst_alone(true_blob), centres_refined = worst_alone(true_refined);
  const double joint_tight = worst_joint(tight_centres, false, &scale_tight);
  const double joint = worst_joint(no_prior, false, &scale_loose);
  const double joint_prior = worst_joint(defaults, true, &scale_prior);
  std::cout << "measured: near rig, " << found.size() << " lights, worst position error (spheres alone): "
            << "each light alone " << alone_blob * 100 << " % (blob centroid) / " << alone * 100 << " % (refined); "
            << "true centres " << centres_blob * 100 << " % / " << centres_refined * 100 << " %; "
            << "jointly with centres held to 0.001 R " << joint_tight * 100 << " %, to 0.05 R " << joint * 100
            << " % (highlight sigma x" << scale_loose << ")\n";
  std::cout << "measured: near rig, jointly with the manifest " << kManifestErrorMm << " mm off as a 10 mm prior: worst "
            << joint_prior * 100 << " % (highlight sigma x" << scale_prior << ")\n";
  EXPECT_LT(centres_refined, kMaxPositionErrorRelative);
  EXPECT_LT(joint, kMaxPositionErrorRelative);
  EXPECT_LT(joint_prior, kMaxPositionErrorRelative);
}

}  // namespace
}  // namespace u3mscan
