// Calibration on whole capture folders written by the synthetic scanner (datasets_synthetic): the
// frames, noise, lens, vignetting and targets of another team's renderer, judged against the rig
// it was given. Cameras are written without pose, so the board must find it.
#include <gtest/gtest.h>

#include <cstdlib>
#include <Eigen/Geometry>
#include <filesystem>
#include <iostream>
#include <unistd.h>

#include "capture/calibrate.h"
#include "capture/capture.h"
#include "core/units.h"
#include "datasets_synthetic/capture_writer.h"
#include "datasets_synthetic/rig.h"
#include "datasets_synthetic/scene.h"
#include "tests/support/image_shift.h"

namespace u3mscan {
namespace {

namespace fs = std::filesystem;

constexpr double kMaxDirectionErrorDeg = 0.5;       // issue 4
constexpr double kMaxPositionErrorRelative = 0.01;  // issue 4
constexpr double kMaxReprojectionErrorPx = 0.2;     // issue 4
constexpr double kMaxPlaneRegistrationPx = 0.25;    // where the found pose puts sample-plane points
constexpr float kAlbedo = 0.5f;

synthetic::SceneTruth FlatWhiteScene(int width, int height, double pitch_mm) {
  synthetic::SceneTruth s;
  s.name = "flat";
  s.pitch_mm = pitch_mm;
  s.height_mm = Image(width, height, 1, 0.0f, pitch_mm);
  s.normal = Image(width, height, 3, 0.0f, pitch_mm);
  for (float& z : s.normal.plane(2)) z = 1.0f;
  s.base_color = Image(width, height, 3, kAlbedo, pitch_mm);
  s.roughness = Image(width, height, 1, 0.5f, pitch_mm);
  for (Image* one : {&s.specular, &s.specular_tint, &s.sheen, &s.sheen_tint, &s.metallic, &s.anisotropic}) {
    *one = Image(width, height, 1, 0.0f, pitch_mm);
  }
  s.alpha = Image(width, height, 1, 1.0f, pitch_mm);
  return s;
}

struct Written {
  fs::path root;
  synthetic::Rig rig;
  ~Written() {
    if (std::getenv("U3MSCAN_KEEP_TEST_CAPTURE")) return;
    std::error_code ignored;
    fs::remove_all(root, ignored);
  }
};

// A capture of `scene` with the named rig and its first `lights` lights (fewer frames: seconds, not minutes).
std::unique_ptr<Written> WriteScene(const synthetic::SceneTruth& scene, const std::string& rig_name,
                                    int width, int height, double pitch_mm, std::size_t lights,
                                    const synthetic::CaptureOptions& options) {
  auto written = std::make_unique<Written>();
  written->root = fs::temp_directory_path() / ("u3mscan_calib_synth_" + rig_name + "_" + std::to_string(::getpid()));
  fs::remove_all(written->root);
  synthetic::RigOptions rig_options;
  rig_options.width = width;
  rig_options.height = height;
  rig_options.pitch_mm = pitch_mm;
  rig_options.seed = 5;
  written->rig = synthetic::MakeRig(rig_name, rig_options);
  if (written->rig.lights.size() > lights) written->rig.lights.resize(lights);
  WriteSyntheticCapture(scene, written->rig, options, written->root);
  return written;
}

std::unique_ptr<Written> WriteCapture(const std::string& rig_name, synthetic::FrameFormat format, int width,
                                      int height, double pitch_mm, std::size_t lights, bool write_pose) {
  synthetic::CaptureOptions options;
  options.format = format;
  options.write_pose = write_pose;
  return WriteScene(FlatWhiteScene(200, 150, 0.25), rig_name, width, height, pitch_mm, lights, options);
}

double AngleDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return RadToDeg(std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0)));
}

void CheckCameras(const CalibrationResult& result, const synthetic::Rig& rig) {
  for (const auto& truth : rig.cameras) {
    const CameraCalibration* found = result.FindCamera(truth.id);
    ASSERT_NE(found, nullptr) << truth.id;
    ASSERT_TRUE(found->reprojection_error_px);
    std::cout << "measured: camera " << truth.id << " (pose from " << found->pose_source << ") board reprojection RMS "
              << *found->reprojection_error_px << " px\n";
    EXPECT_LT(*found->reprojection_error_px, kMaxReprojectionErrorPx);
    CameraModel truth_model = found->model;
    truth_model.pose.rotation = truth.world_from_camera;
    truth_model.pose.translation_mm = truth.position_mm;
    double worst = 0.0;
    for (double x = -20.0; x <= 20.0; x += 5.0) {
      for (double y = -15.0; y <= 15.0; y += 5.0) {
        const Eigen::Vector3d p(x, y, 0.0);
        worst = std::max(worst, (found->model.Project(p) - truth_model.Project(p)).norm());
      }
    }
    std::cout << "measured: camera " << truth.id << " plane registration worst " << worst << " px; pose off by "
              << RadToDeg(Eigen::AngleAxisd(truth.world_from_camera.transpose() * found->model.pose.rotation).angle())
              << " deg and " << (found->model.pose.translation_mm - truth.position_mm).norm() << " mm\n";
    EXPECT_LT(worst, kMaxPlaneRegistrationPx);
  }
}

TEST(SyntheticCapture, DistantRigLightsAndStack) {
  const auto written = WriteCapture("distant", synthetic::FrameFormat::kDng, 320, 240, 0.25, 6, false);  // the RAW path
  const Capture capture = Capture::Open(written->root / synthetic::kCaptureSubdir);
  CalibrationOptions options;
  const CalibrationResult result = Calibrate(capture, options);
  for (const auto& step : result.steps) std::cout << (step.ran ? "ran " : "skipped ") << step.step << ": " << step.detail << "\n";
  for (const auto& w : result.warnings) std::cout << "warning: " << w << "\n";
  CheckCameras(result, written->rig);
  double worst = 0.0;
  for (const auto& truth : written->rig.lights) {
    const LightCalibration* found = result.FindLight(truth.id);
    ASSERT_NE(found, nullptr);
    EXPECT_EQ(found->source, "mirror sphere") << truth.id;
    const double error = AngleDeg(found->model.direction_in_world, truth.direction);
    std::cout << "measured: light " << truth.id << " direction error " << error << " deg\n";
    worst = std::max(worst, error);
  }
  std::cout << "measured: synthetic distant rig, worst light direction error " << worst << " deg\n";
  EXPECT_LT(worst, kMaxDirectionErrorDeg);
  EXPECT_TRUE(result.colour.fitted);
  if (result.colour.fitted) {
    EXPECT_LT(result.colour.fit.delta_e_after_mean, 1.5);
  }

  // The stack of a flat sample of albedo 0.5: pi * rgb / (cos * E) is the albedo everywhere.
  const Stack stack = BuildStack(capture, result, options);
  ASSERT_EQ(stack.observations.size(), written->rig.lights.size());
  const Observation& o = stack.observations.front();
  const LightModel& light = stack.lights[o.light];
  double sum = 0.0;
  int n = 0;
  for (int row = stack.grid.height / 4; row < 3 * stack.grid.height / 4; ++row) {
    for (int col = stack.grid.width / 4; col < 3 * stack.grid.width / 4; ++col) {
      if (!o.flags.empty() && o.flags[row * stack.grid.width + col]) continue;
      const Eigen::Vector3d p = stack.grid.PixelCentreInWorld(col, row);
      const double e = o.irradiance.empty() ? light.RelativeIrradianceAt(p) : o.irradiance.at(0, row, col);
      sum += kPi * o.rgb.at(1, row, col) / (light.DirectionFrom(p).z() * e);
      ++n;
    }
  }
  ASSERT_GT(n, 0);
  std::cout << "measured: synthetic distant rig, recovered albedo " << sum / n << " (truth " << kAlbedo << ")\n";
  EXPECT_NEAR(sum / n, kAlbedo, 0.02);
}

TEST(SyntheticCapture, NearRigPointLightPositions) {
  // Six lights: enough spare equations (6 x 3 highlights x 2 - 6 centre - 18 light unknowns = 12)
  // for the joint fit to scale the highlights' sigma from their scatter (light_joint_fit.h).
  constexpr std::size_t kNearRigLights = 6;
  const auto written = WriteCapture("near", synthetic::FrameFormat::kExr, 320, 240, 0.25, kNearRigLights, true);
  // The synthetic manifest holds the true positions; a real scanner's are design values. Move
  // each by 15 mm (a fixed pattern) so the spheres have something to correct.
  const fs::path capture_dir = written->root / synthetic::kCaptureSubdir;
  Manifest manifest = ReadManifest(capture_dir);
  constexpr double kManifestErrorMm = 15.0;
  for (std::size_t i = 0; i < manifest.lights.size(); ++i) {
    const double a = 2.399 * i;  // golden-angle turns: offsets in every direction
    *manifest.lights[i].position_mm +=
        kManifestErrorMm * Eigen::Vector3d(std::cos(a), std::sin(a), (i % 2) ? 0.5 : -0.5).normalized();
  }
  WriteManifest(manifest, capture_dir);
  const Capture capture = Capture::Open(capture_dir);
  const CalibrationResult result = Calibrate(capture, CalibrationOptions{});
  for (const auto& step : result.steps) std::cout << (step.ran ? "ran " : "skipped ") << step.step << ": " << step.detail << "\n";
  for (const auto& w : result.warnings) std::cout << "warning: " << w << "\n";
  CheckCameras(result, written->rig);
  // Three placements ~50 mm apart, 400 mm below the lights. Judged against issue 4: every light's
  // direction from the sample centre within 0.5 deg, its position within 1 % of its distance, both
  // with the manifest's (15 mm off) position as the default prior and from the spheres alone.
  double worst_direction = 0.0, worst_position = 0.0;
  for (const auto& truth : written->rig.lights) {
    const LightCalibration* found = result.FindLight(truth.id);
    ASSERT_NE(found, nullptr);
    EXPECT_EQ(found->source, "mirror sphere") << truth.id;
    const double direction_error = AngleDeg(found->model.position_in_world_mm, truth.position_mm);
    const double position_error = (found->model.position_in_world_mm - truth.position_mm).norm();
    const double manifest_error = (*manifest.FindLight(truth.id)->position_mm - truth.position_mm).norm();
    std::cout << "measured: light " << truth.id << " direction error " << direction_error << " deg, position error "
              << position_error << " mm (" << position_error / truth.position_mm.norm() * 100.0 << " %; manifest "
              << manifest_error << " mm); " << found->note << "\n";
    worst_direction = std::max(worst_direction, direction_error);
    worst_position = std::max(worst_position, position_error / truth.position_mm.norm());
    EXPECT_LT(direction_error, kMaxDirectionErrorDeg) << truth.id;
    EXPECT_LT(position_error, kMaxPositionErrorRelative * truth.position_mm.norm()) << truth.id;
  }
  {
    // The same spheres without the manifest prior: what triangulation alone gives.
    CalibrationOptions no_prior;
    no_prior.light_fit.manifest_position_sigma_mm = 0.0;
    const CalibrationResult triangulated = Calibrate(capture, no_prior);
    double worst_triangulated = 0.0;
    for (const auto& truth : written->rig.lights) {
      const LightCalibration* found = triangulated.FindLight(truth.id);
      worst_triangulated = std::max(worst_triangulated,
                                    (found->model.position_in_world_mm - truth.position_mm).norm() / truth.position_mm.norm());
    }
    EXPECT_LT(worst_triangulated, kMaxPositionErrorRelative);
    std::cout << "measured: synthetic near rig without the manifest prior (" << triangulated.lights[0].placements
              << " placements): worst position error " << worst_triangulated * 100.0 << " %\n";
  }
  std::cout << "measured: synthetic near rig, worst direction error " << worst_direction
            << " deg, worst position error " << worst_position * 100.0 << " % of the distance\n";
}

TEST(SyntheticCapture, ObliqueRigBothViewsOnOneGrid) {
  // The top camera and the oblique one (about 60 deg), both posed by the board, rectified onto one
  // grid: a flat sample of one albedo must read the same in both views, pixel for pixel.
  const auto written = WriteCapture("oblique", synthetic::FrameFormat::kExr, 320, 240, 0.25, 2, false);
  const Capture capture = Capture::Open(written->root / synthetic::kCaptureSubdir);
  const CalibrationResult result = Calibrate(capture, CalibrationOptions{});
  for (const auto& step : result.steps) std::cout << (step.ran ? "ran " : "skipped ") << step.step << ": " << step.detail << "\n";
  for (const auto& w : result.warnings) std::cout << "warning: " << w << "\n";
  ASSERT_EQ(result.cameras.size(), 2u);
  CheckCameras(result, written->rig);
  const Stack stack = BuildStack(capture, result, CalibrationOptions{});
  ASSERT_EQ(stack.views.size(), 2u);
  // Albedo from each view over the central half of the grid.
  double albedo[2] = {0, 0};
  int count[2] = {0, 0};
  for (const Observation& o : stack.observations) {
    const LightModel& light = stack.lights[o.light];
    for (int row = stack.grid.height / 4; row < 3 * stack.grid.height / 4; ++row) {
      for (int col = stack.grid.width / 4; col < 3 * stack.grid.width / 4; ++col) {
        if (!o.flags.empty() && o.flags[row * stack.grid.width + col]) continue;
        const Eigen::Vector3d p = stack.grid.PixelCentreInWorld(col, row);
        const double e = o.irradiance.empty() ? light.RelativeIrradianceAt(p) : o.irradiance.at(0, row, col);
        albedo[o.view] += kPi * o.rgb.at(1, row, col) / (light.DirectionFrom(p).z() * e);
        ++count[o.view];
      }
    }
  }
  ASSERT_GT(count[0], 0);
  ASSERT_GT(count[1], 0);
  std::cout << "measured: oblique rig, albedo from the top view " << albedo[0] / count[0] << ", from the oblique view "
            << albedo[1] / count[1] << " (truth " << kAlbedo << ")\n";
  EXPECT_NEAR(albedo[0] / count[0], kAlbedo, 0.02);
  EXPECT_NEAR(albedo[1] / count[1], kAlbedo, 0.02);
}

// A sample 1 mm thick seen by
// the top camera and the oblique one (about 60 deg): a flat face lifted 1 mm off the table, printed
// with cells of random albedo. The synthetic scanner writes its thickness;
// the maps are made on the sample's face, so the two views' images of one light register on the
// grid. Made on the table plane z = 0 instead (thickness left out of the manifest), the oblique
// view is shifted by t tan(theta), 6-9 grid pixels: that misregistration is what the plane
// removes.
constexpr double kThickSampleMm = 1.0;
constexpr double kMaxViewRegistrationPx = 0.1;   // grid px, between the views on the sample's face (measured 0.02)
constexpr double kMinTableShiftPx = 4.0;         // grid px, with the maps on z = 0 (4 tan(55..65 deg) = 5.7..8.6)

synthetic::SceneTruth RaisedPrintScene(int width, int height, double pitch_mm) {
  synthetic::SceneTruth s = FlatWhiteScene(width, height, pitch_mm);
  s.name = "raised print";
  for (float& h : s.height_mm.plane(0)) h = static_cast<float>(kThickSampleMm);
  testing::PaintRandomPrint(&s.base_color, 4, 0.15f, 0.7f);
  return s;
}

// Shift of the oblique view's image of the (one) light against the top view's.
Eigen::Vector2d ObliqueShiftPx(const Stack& stack) {
  const Observation* views[2] = {nullptr, nullptr};
  for (const Observation& o : stack.observations) {
    if (o.view >= 0 && o.view < 2) views[o.view] = &o;
  }
  if (!views[0] || !views[1]) return Eigen::Vector2d::Constant(1e9);
  return testing::ShiftPx(views[0]->rgb, views[1]->rgb, testing::CentralHalf(views[0]->rgb));
}

TEST(SyntheticCapture, ObliqueViewRegistersOnTheFaceOfAThickSample) {
  synthetic::CaptureOptions options;
  options.format = synthetic::FrameFormat::kExr;
  options.calibration_frames = false;  // geometry from the manifest: only the plane is under test
  const auto written = WriteScene(RaisedPrintScene(200, 150, 0.25), "oblique", 320, 240, 0.25, 1, options);
  const Capture capture = Capture::Open(written->root / synthetic::kCaptureSubdir);
  ASSERT_TRUE(capture.manifest().sample.thickness_mm);
  EXPECT_NEAR(*capture.manifest().sample.thickness_mm, kThickSampleMm, 1e-6);

  const CalibrationResult on_face = Calibrate(capture, CalibrationOptions{});
  EXPECT_NEAR(on_face.surface_z_mm, kThickSampleMm, 1e-6);
  EXPECT_NEAR(on_face.ToJson()["grid"]["surface_z_mm"].get<double>(), kThickSampleMm, 1e-6);
  const Eigen::Vector2d face_shift = ObliqueShiftPx(BuildStack(capture, on_face, CalibrationOptions{}));

  Manifest without = capture.manifest();
  without.sample.thickness_mm.reset();
  const FrameLoader load = [&capture](std::size_t index) { return capture.LoadFrame(index); };
  const CalibrationResult on_table = Calibrate(without, load, CalibrationOptions{});
  EXPECT_EQ(on_table.surface_z_mm, 0.0);
  const Eigen::Vector2d table_shift = ObliqueShiftPx(BuildStack(without, load, on_table, CalibrationOptions{}));

  std::cout << "measured: oblique view against the top view, maps on the sample's face " << face_shift.transpose()
            << " px, on the table plane " << table_shift.transpose() << " px\n";
  EXPECT_LT(face_shift.norm(), kMaxViewRegistrationPx);
  EXPECT_GT(table_shift.norm(), kMinTableShiftPx);
}

}  // namespace
}  // namespace u3mscan
