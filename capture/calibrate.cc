#include "capture/calibrate.h"
#include "capture/stack_builder.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <sstream>

#include "capture/camera_calibration.h"
#include "capture/capture.h"
#include "capture/flat_field.h"
#include "capture/light_calibration.h"
#include "capture/light_joint_fit.h"
#include "capture/rectification.h"
#include "core/error.h"
#include "core/logging.h"
#include "core/parallel.h"
#include "core/units.h"

namespace u3mscan {
namespace {

std::vector<std::size_t> FramesWith(const Manifest& manifest, FrameRole role, const std::string* camera = nullptr,
                                    const std::string* light = nullptr, const std::string* side = nullptr) {
  std::vector<std::size_t> out;
  for (std::size_t i = 0; i < manifest.frames.size(); ++i) {
    const FrameSpec& f = manifest.frames[i];
    if (f.role != role) continue;
    if (camera && f.camera != *camera) continue;
    if (light && f.light.value_or("") != *light) continue;
    if (side && f.side != *side) continue;
    out.push_back(i);
  }
  return out;
}

std::string FrameField(std::size_t index) { return "/frames/" + std::to_string(index); }

class Recorder {
 public:
  explicit Recorder(CalibrationResult& result) : result_(result) {}
  void Ran(const std::string& step, const std::string& detail) {
    result_.steps.push_back({step, true, detail});
    LogInfo() << "calibrate: " << step << ": " << detail;
  }
  void Skipped(const std::string& step, const std::string& reason) {
    result_.steps.push_back({step, false, reason});
    LogInfo() << "calibrate: " << step << " skipped: " << reason;
  }
  void Warn(const std::string& message) {
    result_.warnings.push_back(message);
    LogWarning() << "calibrate: " << message;
  }

 private:
  CalibrationResult& result_;
};

// Loads a frame and takes dark (and for samples ambient) away.
DecodedFrame LoadCorrected(const Manifest& manifest, const FrameLoader& load, const DarkAmbient& dark_ambient,
                           std::size_t index) {
  DecodedFrame frame = load(index);
  dark_ambient.Apply(manifest.frames[index], frame.rgb);
  return frame;
}

void CalibrateCameras(const Manifest& manifest, const FrameLoader& load, const CalibrationOptions& options,
                      const std::string& manifest_file, CalibrationResult& result, Recorder& record) {
  for (std::size_t c = 0; c < manifest.cameras.size(); ++c) {
    const CameraSpec& spec = manifest.cameras[c];
    bool has_frames = false;
    for (const auto& f : manifest.frames) has_frames = has_frames || f.camera == spec.id;
    const std::string step = "camera " + spec.id;
    if (!has_frames) {
      record.Skipped(step, "no frames of this camera");
      continue;
    }
    CameraCalibration calibration;
    calibration.id = spec.id;
    calibration.model = CameraModel::FromSpec(spec);
    const auto board_indices = FramesWith(manifest, FrameRole::kBoard, &spec.id);
    std::vector<BoardObservation> observations;
    std::vector<std::string> board_errors;
    if (!board_indices.empty() && !manifest.targets.board) {
      record.Warn("board frames of camera " + spec.id + " but no /targets/board in " + manifest_file +
                  ": board frames ignored");
    } else {
      for (std::size_t index : board_indices) {
        try {
          DecodedFrame frame = LoadCorrected(manifest, load, result.dark_ambient, index);
          observations.push_back(DetectBoard(frame.rgb, *manifest.targets.board, manifest.frames[index].file,
                                             options.min_board_corners));
        } catch (const InputError& error) {
          board_errors.push_back(error.what());
          record.Warn(std::string(error.what()) + " (frame skipped)");
        }
      }
    }
    std::ostringstream detail;
    if (options.calibrate_intrinsics &&
        static_cast<int>(observations.size()) >= std::max(3, options.min_board_frames_for_intrinsics)) {
      const IntrinsicsFit fit = CalibrateIntrinsics(spec.width, spec.height, *manifest.targets.board, observations,
                                                    spec.intrinsics);
      calibration.model.intrinsics = fit.intrinsics;
      calibration.model.distortion = fit.distortion;
      calibration.intrinsics_source = "board frames";
      calibration.reprojection_error_px = fit.reprojection_error_px;
      detail << "intrinsics and distortion from " << observations.size() << " board frames (RMS "
             << fit.reprojection_error_px << " px); ";
    } else {
      detail << "intrinsics from the manifest; ";
    }
    for (const auto& o : observations) calibration.board_frames.push_back(o.frame_file);
    if (spec.pose) {
      calibration.model.pose = *spec.pose;
      detail << "pose from the manifest";
      if (!observations.empty()) {
        // A check of the manifest's pose against the board, reported, not acted on.
        calibration.reprojection_error_px =
            BoardReprojectionErrorPx(calibration.model, *manifest.targets.board, observations.front());
        detail << " (board " << observations.front().frame_file << " reprojects with RMS "
               << *calibration.reprojection_error_px << " px)";
      }
    } else {
      if (observations.empty()) {
        std::string why = board_indices.empty() ? "no board frame of this camera" : "";
        for (const auto& e : board_errors) why += (why.empty() ? "" : "; ") + e;
        throw InputError(manifest_file, "/cameras/" + std::to_string(c) + "/pose",
                         "a pose for camera " + spec.id + ", or a board frame in which the ChArUco board is found (" +
                             why + ")");
      }
      // The view that sees the board best (most corners) gives the pose, with every other board
      // frame that shows the board in the same place (their corners pooled).
      std::vector<std::string> used;
      const BoardPose pose = EstimateBoardPoseFromFrames(calibration.model, *manifest.targets.board, observations, &used);
      std::string frames;
      for (const auto& f : used) frames += (frames.empty() ? "" : ", ") + f;
      calibration.model.pose = pose.pose;
      calibration.pose_source = (used.size() > 1 ? "board frames " : "board frame ") + frames;
      calibration.reprojection_error_px = pose.reprojection_error_px;
      detail << "pose from " << calibration.pose_source << " (" << pose.corners << " corners, RMS "
             << pose.reprojection_error_px << " px)";
    }
    record.Ran(step, detail.str());
    result.cameras.push_back(std::move(calibration));
  }
}

void ChooseResultGrid(const Manifest& manifest, const CalibrationOptions& options, const std::string& manifest_file,
                      CalibrationResult& result, Recorder& record) {
  std::vector<CameraModel> sample_cameras;
  for (const auto& camera : result.cameras) {
    if (!FramesWith(manifest, FrameRole::kSample, &camera.id).empty()) sample_cameras.push_back(camera.model);
  }
  OutputSpec output = manifest.output;
  if (options.dpi) output.dpi = options.dpi;
  if (options.region_mm) output.region_mm = options.region_mm;
  if (sample_cameras.empty()) {
    for (const auto& camera : result.cameras) sample_cameras.push_back(camera.model);
  }
  result.surface_z_mm = SampleSurfaceZMm(manifest);
  result.grid = ChooseGrid(sample_cameras, output, manifest_file, result.surface_z_mm);
  std::ostringstream detail;
  detail << result.grid.width << " x " << result.grid.height << " px at " << result.grid.dpi() << " dpi ("
         << result.grid.pitch_mm << " mm), top-left (" << result.grid.x0_mm << ", " << result.grid.y1_mm << ") mm"
         << (output.region_mm ? "" : ", region seen whole by every sample camera")
         << (output.dpi ? "" : ", native resolution") << ", on the plane z = " << result.surface_z_mm << " mm"
         << (manifest.sample.thickness_mm ? " (the sample's face: sample.thickness_mm)"
                                          : " (no sample.thickness_mm: a thick sample's maps are off in scale and, "
                                            "from a tilted camera, shifted)");
  record.Ran("grid", detail.str());
}

// A point light seen on one sphere placement: its distance along the sphere's ray from the
// shading of its flat frame (light_from_plane.h). Without a flat frame, or with an ill-conditioned
// fit, the light keeps the distance the sphere fit gave (the manifest's), and the log says why.
void DistanceFromFlat(const Manifest& manifest, const FrameLoader& load, const CalibrationOptions& options,
                      const CalibrationResult& done, const SphereObservation& sphere, LightCalibration& calibration,
                      Recorder& record) {
  const std::string step = "light " + calibration.model.id + " distance from flat";
  const std::string keep = ": distance along the sphere's ray from the manifest";
  const std::string& id = calibration.model.id;
  std::optional<std::size_t> flat_index;
  for (std::size_t index : FramesWith(manifest, FrameRole::kFlat, nullptr, &id)) {
    if (done.FindCamera(manifest.frames[index].camera)) {
      flat_index = index;
      break;
    }
  }
  if (!flat_index) {
    record.Skipped(step, "one sphere placement and no flat frame of this light" + keep);
    return;
  }
  if (!manifest.targets.white) {
    record.Skipped(step, "no /targets/white for the flat frame" + keep);
    return;
  }
  const FrameSpec& spec = manifest.frames[*flat_index];
  try {
    const DecodedFrame flat = LoadCorrected(manifest, load, done.dark_ambient, *flat_index);
    const MetricGrid& g = done.grid;
    const std::array<double, 4> region{g.x0_mm, g.y1_mm - g.height * g.pitch_mm, g.x0_mm + g.width * g.pitch_mm, g.y1_mm};
    const Eigen::Vector3d ray = (calibration.model.position_in_world_mm - sphere.highlight_point_in_world_mm).normalized();
    const PlaneLightFit fit = FitPointLightOnPlane(flat.rgb, flat.saturated, done.FindCamera(spec.camera)->model,
                                                   calibration.model, sphere.highlight_point_in_world_mm, ray, region,
                                                   spec.file, options.light_fit.plane);
    std::ostringstream detail;
    detail << "distance " << fit.distance_mm << " mm along the sphere's ray (1-sigma " << fit.sigma_mm
           << " mm) from " << fit.samples << " points of " << spec.file << ", shading residual "
           << fit.residual_rms * 100.0 << " % RMS";
    if (fit.exponent_fitted) detail << ", profile exponent fitted " << fit.model.profile_exponent;
    if (!fit.ok) {
      record.Warn(fit.reason + keep);
      record.Skipped(step, fit.reason + keep);
      return;
    }
    calibration.model = fit.model;
    calibration.source = "mirror sphere + flat";
    calibration.note += (calibration.note.empty() ? "" : "; ") + detail.str();
    detail << "; position (" << fit.model.position_in_world_mm.transpose() << ") mm";
    record.Ran(step, detail.str());
  } catch (const InputError& error) {
    record.Warn(std::string(error.what()) + keep);
    record.Skipped(step, std::string(error.what()) + keep);
  }
}

void CalibrateLights(const Manifest& manifest, const FrameLoader& load, const CalibrationOptions& options,
                     const CalibrationResult& done, CalibrationResult& result, Recorder& record) {
  struct Pending {
    std::size_t light;  // index into result.lights
    std::vector<SphereObservation> observations;
  };
  std::vector<Pending> pending;
  for (const LightSpec& spec : manifest.lights) {
    LightCalibration calibration;
    calibration.model = LightModelFromSpec(spec);
    const std::string step = "light " + spec.id;
    const auto sphere_indices = FramesWith(manifest, FrameRole::kSphere, nullptr, &spec.id);
    if (sphere_indices.empty()) {
      record.Skipped(step, "no mirror-sphere frames: position/direction from the manifest");
      result.lights.push_back(std::move(calibration));
      continue;
    }
    if (!manifest.targets.sphere) {
      record.Warn("sphere frames for light " + spec.id + " but no /targets/sphere: light taken from the manifest");
      record.Skipped(step, "no /targets/sphere: position/direction from the manifest");
      result.lights.push_back(std::move(calibration));
      continue;
    }
    // One placement may use the manifest's centre_mm; several placements are found in their frames.
    // A pose found from one board view maps the sample plane to within a tenth of a pixel but can
    // be off along the tilt/translation trade-off for points above it (the sphere): the sphere's
    // centre found in the frame under that same pose then absorbs part of the error, so it is
    // preferred to the manifest's centre for such cameras (which stays the fall-back).
    const bool known_centre_available = sphere_indices.size() == 1 && manifest.targets.sphere->center_mm.has_value();
    std::optional<double> centre_height;
    if (options.sphere_on_known_height) {
      centre_height = manifest.targets.sphere->center_mm ? manifest.targets.sphere->center_mm->z()
                                                         : manifest.targets.sphere->radius_mm;
    }
    std::vector<SphereObservation> observations;
    for (std::size_t index : sphere_indices) {
      const FrameSpec& frame_spec = manifest.frames[index];
      const CameraCalibration* camera = done.FindCamera(frame_spec.camera);
      if (!camera) continue;
      try {
        DecodedFrame frame = LoadCorrected(manifest, load, result.dark_ambient, index);
        const bool pose_from_manifest = camera->pose_source == "manifest";
        if (known_centre_available && pose_from_manifest) {
          observations.push_back(ObserveSphere(frame.rgb, camera->model, *manifest.targets.sphere, frame_spec.file,
                                               manifest.targets.sphere->center_mm));
        } else {
          try {
            observations.push_back(
                ObserveSphere(frame.rgb, camera->model, *manifest.targets.sphere, frame_spec.file, std::nullopt,
                              centre_height));
          } catch (const InputError& error) {
            if (!known_centre_available) throw;
            LogInfo() << "calibrate: " << error.what() << "; using the manifest's sphere centre";
            observations.push_back(ObserveSphere(frame.rgb, camera->model, *manifest.targets.sphere, frame_spec.file,
                                                 manifest.targets.sphere->center_mm));
          }
        }
        calibration.sphere_frames.push_back(frame_spec.file);
      } catch (const InputError& error) {
        record.Warn(std::string(error.what()) + " (frame skipped)");
      }
    }
    if (observations.empty()) {
      record.Warn("light " + spec.id + ": no usable mirror-sphere frame, position/direction from the manifest");
      record.Skipped(step, "no usable mirror-sphere frame: position/direction from the manifest");
      result.lights.push_back(std::move(calibration));
      continue;
    }
    pending.push_back({result.lights.size(), std::move(observations)});
    result.lights.push_back(std::move(calibration));
  }
  // Every light with sphere observations: fitted alone, or jointly with the others over shared
  // sphere placements (light_joint_fit.h).
  std::vector<LightFit> fits;
  if (options.joint_light_fit && !pending.empty()) {
    std::vector<JointLightInput> inputs;
    for (auto& p : pending) inputs.push_back({result.lights[p.light].model, p.observations});
    JointLightFit joint = FitLightsJointly(inputs, options.light_fit);
    fits = std::move(joint.lights);
    std::ostringstream detail;
    detail << pending.size() << " light(s) and " << joint.placements << " sphere placement(s) fitted jointly, centres moved "
           << joint.centre_shift_rms_mm << " mm RMS from their frames' mean" << (joint.converged ? "" : " (not converged)");
    record.Ran("lights jointly", detail.str());
  } else {
    for (auto& p : pending) {
      const LightModel& start = result.lights[p.light].model;
      fits.push_back(start.type == LightType::kDirectional ? FitDirectionalLight(p.observations, start)
                                                           : FitPointLight(p.observations, start, options.light_fit));
    }
  }
  for (std::size_t k = 0; k < pending.size(); ++k) {
    const LightFit& fit = fits[k];
    LightCalibration& calibration = result.lights[pending[k].light];
    calibration.model = fit.model;
    calibration.source = "mirror sphere";
    calibration.placements = fit.placements;
    calibration.residual = fit.residual;
    calibration.residual_unit = fit.residual_unit;
    calibration.note = fit.note;
    std::ostringstream detail;
    if (fit.model.type == LightType::kDirectional) {
      detail << "direction (" << fit.model.direction_in_world.transpose() << ")";
    } else {
      detail << "position (" << fit.model.position_in_world_mm.transpose() << ") mm";
    }
    detail << " from " << fit.placements << " sphere placement(s), residual " << fit.residual << " "
           << fit.residual_unit << (fit.note.empty() ? "" : "; " + fit.note);
    record.Ran("light " + calibration.model.id, detail.str());
    if (fit.model.type == LightType::kPoint && pending[k].observations.size() == 1 &&
        options.light_fit.distance_from_flat) {
      DistanceFromFlat(manifest, load, options, done, pending[k].observations.front(), calibration, record);
    }
  }
}

void CalibrateFlats(const Manifest& manifest, const FrameLoader& load, const CalibrationOptions& options,
                    CalibrationResult& result, Recorder& record) {
  const auto flat_indices = FramesWith(manifest, FrameRole::kFlat);
  if (flat_indices.empty()) {
    record.Skipped("flat field", "no flat frames: the analytic light model (inverse square, cos^n) is used");
    return;
  }
  if (!manifest.targets.white) {
    record.Warn("flat frames but no /targets/white reflectance: flats ignored, the analytic light model is used");
    record.Skipped("flat field", "no /targets/white: the analytic light model is used");
    return;
  }
  std::map<std::string, RectificationMap> maps;
  std::map<std::tuple<std::string, std::string, std::string>, std::pair<FlatCalibration, int>> sums;
  for (std::size_t index : flat_indices) {
    const FrameSpec& spec = manifest.frames[index];
    const CameraCalibration* camera = result.FindCamera(spec.camera);
    const LightCalibration* light = spec.light ? result.FindLight(*spec.light) : nullptr;
    if (!camera || !light) {
      record.Warn(spec.file + ": a flat frame needs a calibrated camera and a light (frame skipped)");
      continue;
    }
    try {
      DecodedFrame flat = LoadCorrected(manifest, load, result.dark_ambient, index);
      // The flat must outshine the fabric under the same light: a swapped or unlit frame would
      // otherwise turn into a wildly wrong irradiance.
      const auto samples = FramesWith(manifest, FrameRole::kSample, &spec.camera, &*spec.light, &spec.side);
      if (!samples.empty()) {
        const DecodedFrame sample = LoadCorrected(manifest, load, result.dark_ambient, samples.front());
        CheckFlatBrighterThanSample(flat.rgb, spec, index, sample.rgb, manifest.frames[samples.front()]);
      }
      auto map_it = maps.find(spec.camera);
      if (map_it == maps.end()) map_it = maps.emplace(spec.camera, BuildRectificationMap(camera->model, result.grid, result.surface_z_mm)).first;
      const Image on_grid = RectifyImage(flat.rgb, map_it->second);
      Image irradiance = MeasuredIrradiance(on_grid, spec, light->model, result.grid,
                                            manifest.targets.white->reflectance, options.min_flat_cos);
      // Out-of-view grid pixels carry no measurement.
      for (std::size_t i = 0; i < irradiance.pixel_count(); ++i) {
        if (map_it->second.out_of_view[i]) irradiance.data()[i] = 0.0f;
      }
      auto key = std::make_tuple(spec.camera, *spec.light, spec.side);
      auto [it, inserted] = sums.try_emplace(key);
      if (inserted) {
        it->second.first = FlatCalibration{spec.camera, *spec.light, spec.side, {}, std::move(irradiance)};
      } else {
        auto& sum = it->second.first.irradiance.data();
        for (std::size_t i = 0; i < sum.size(); ++i) sum[i] += irradiance.data()[i];
      }
      it->second.first.frames.push_back(spec.file);
      ++it->second.second;
    } catch (const InputError& error) {
      record.Warn(std::string(error.what()) + " (flat skipped: the analytic light model is used for it)");
    }
  }
  for (auto& [key, entry] : sums) {
    auto& [flat, count] = entry;
    for (float& v : flat.irradiance.data()) v /= static_cast<float>(count);
    record.Ran("flat " + flat.camera + "/" + flat.light + "/" + flat.side,
               "measured irradiance from " + std::to_string(count) + " flat frame(s), mean " +
                   std::to_string(flat.irradiance.ChannelMean(0)));
    result.flats.push_back(std::move(flat));
  }
}

void CalibrateColour(const Manifest& manifest, const FrameLoader& load, const CalibrationOptions& options,
                     CalibrationResult& result, Recorder& record) {
  const auto chart_indices = FramesWith(manifest, FrameRole::kChart);
  if (chart_indices.empty()) {
    record.Skipped("colour", "no chart frames: colour correction skipped");
    return;
  }
  if (manifest.targets.chart && !manifest.targets.chart->type.empty()) {
    std::string type = manifest.targets.chart->type;
    std::transform(type.begin(), type.end(), type.begin(), [](unsigned char ch) { return std::tolower(ch); });
    if (type.find("24") == std::string::npos && type.find("macbeth") == std::string::npos &&
        type.find("classic") == std::string::npos) {
      record.Warn("chart type \"" + manifest.targets.chart->type + "\" is not a classic 24-patch chart");
      record.Skipped("colour", "chart type not supported: colour correction skipped");
      return;
    }
  }
  const auto& reference = ClassicChartLinearSrgb();
  for (std::size_t index : chart_indices) {
    const FrameSpec& spec = manifest.frames[index];
    const CameraCalibration* camera = result.FindCamera(spec.camera);
    const LightCalibration* light = spec.light ? result.FindLight(*spec.light) : nullptr;
    if (!camera || !light) {
      record.Warn(spec.file + ": a chart frame needs a calibrated camera and a light (frame skipped)");
      continue;
    }
    try {
      const DecodedFrame frame = LoadCorrected(manifest, load, result.dark_ambient, index);
      std::optional<std::vector<ChartPatch>> patches;
      std::string locator;
      if (options.use_mcc) {
        patches = MeasureChartWithMcc(frame.rgb);
        locator = "mcc";
      }
      if (!patches) {
        if (options.use_mcc) LogInfo() << "calibrate: mcc found no chart in " << spec.file << ", using the known layout";
        ChartLayout layout = options.chart_layout;
        locator = "known layout";
        if (!(layout.patch_pitch_mm > 0.0)) {
          layout.patch_pitch_mm = FindChartPitchMm(frame.rgb, camera->model, layout.centre_mm);
          if (!(layout.patch_pitch_mm > 0.0)) {
            throw InputError(spec.file, "", "a 24-patch colour chart (mcc found none, and none fits in the view centred on (" +
                                                std::to_string(layout.centre_mm.x()) + ", " +
                                                std::to_string(layout.centre_mm.y()) + ") mm)");
          }
          std::ostringstream how;
          how << "known layout, pitch " << layout.patch_pitch_mm << " mm searched";
          locator = how.str();
        }
        patches = MeasureChartAtLayout(frame.rgb, camera->model, layout, spec.file);
      }
      // Patch readings -> reflectance: divide by exposure, intensity, cosine and irradiance (the
      // measured flat where there is one).
      const FlatCalibration* flat = result.FindFlat(spec.camera, *spec.light, spec.side);
      std::vector<Rgb> measured;
      for (const ChartPatch& patch : *patches) {
        Eigen::Vector3d point;
        if (!camera->model.PixelToPlane(patch.centre_px, 0.0, &point)) {
          throw InputError(spec.file, "", "a colour chart on the sample plane");
        }
        double irradiance = light->model.RelativeIrradianceAt(point);
        if (flat) {
          const int col = static_cast<int>(std::floor((point.x() - result.grid.x0_mm) / result.grid.pitch_mm));
          const int row = static_cast<int>(std::floor((result.grid.y1_mm - point.y()) / result.grid.pitch_mm));
          if (col >= 0 && row >= 0 && col < result.grid.width && row < result.grid.height &&
              flat->irradiance.at(0, row, col) > 0.0f) {
            irradiance = flat->irradiance.at(0, row, col);
          }
        }
        const double cos_theta = light->model.DirectionFrom(point).z();
        Rgb rho{};
        for (int c = 0; c < 3; ++c) {
          rho[c] = kPi * patch.mean_rgb[c] /
                   (spec.exposure_s * light->model.intensity_rgb[c] * std::max(1e-6, cos_theta) * irradiance);
        }
        measured.push_back(rho);
      }
      const ColourFit fit = FitColourCorrection(measured, {reference.begin(), reference.end()});
      if (!(fit.delta_e_after_mean < options.max_chart_delta_e)) {
        std::ostringstream what;
        what << "a 24-patch colour chart (found by " << locator << "); its patches do not match the chart: CIEDE2000 mean "
             << fit.delta_e_after_mean << " even after a 3x3 fit (at most " << options.max_chart_delta_e << " expected)";
        throw InputError(spec.file, "", what.str());
      }
      ColourCalibration colour{true, false, "", spec.file, locator, ChartPatchPitchPx(*patches), fit};
      std::ostringstream reason;
      if (colour.patch_pitch_px < options.min_chart_patch_pitch_px) {
        reason << "the chart is too small to trust: its patches are " << colour.patch_pitch_px
               << " px apart in the frame, at least " << options.min_chart_patch_pitch_px
               << " px needed to sample their centres clear of their edges";
        record.Warn(spec.file + ": " + reason.str() + "; colour correction not applied (camera RGB used as is)");
      } else if (!(fit.delta_e_cross_validated_mean < fit.delta_e_before_mean)) {
        reason << "the camera's colours are already closer to the chart than the matrix brings patches it was not "
                  "fitted to (leave-one-out CIEDE2000 mean "
               << fit.delta_e_cross_validated_mean << ")";
      }
      colour.not_applied_reason = reason.str();
      colour.applied = colour.not_applied_reason.empty();
      result.colour = colour;
      std::ostringstream detail;
      detail << "3x3 correction from " << spec.file << " (chart by " << locator << ", patches " << colour.patch_pitch_px
             << " px apart): CIEDE2000 mean " << fit.delta_e_before_mean << " before, " << fit.delta_e_after_mean
             << " after (max " << fit.delta_e_after_max << "), " << fit.delta_e_cross_validated_mean
             << " leave-one-out" << (colour.applied ? "" : "; not applied: " + colour.not_applied_reason);
      record.Ran("colour", detail.str());
      return;
    } catch (const InputError& error) {
      record.Warn(std::string(error.what()) + " (chart frame skipped)");
    }
  }
  record.Skipped("colour", "no chart found in any chart frame: colour correction skipped");
}

nlohmann::json Vector(const Eigen::Vector3d& v) { return nlohmann::json::array({v.x(), v.y(), v.z()}); }

}  // namespace

bool CalibrationOptions::Check() const {
  return (side == "front" || side == "back") && (!dpi || *dpi > 0.0) && min_board_frames_for_intrinsics >= 3 &&
         min_board_corners >= 4 && chart_layout.patch_pitch_mm >= 0.0 && min_flat_cos > 0.0 && min_flat_cos < 1.0 &&
         max_chart_delta_e > 0.0 && min_chart_patch_pitch_px >= 0.0;
}

LightModel LightModelFromSpec(const LightSpec& spec) {
  LightModel model;
  model.id = spec.id;
  model.type = spec.type == ManifestLightType::kPoint ? LightType::kPoint : LightType::kDirectional;
  if (spec.direction) model.direction_in_world = spec.direction->normalized();
  if (spec.position_mm) {
    model.position_in_world_mm = *spec.position_mm;
    if (!spec.direction) model.direction_in_world = spec.position_mm->normalized();
  }
  model.intensity_rgb = spec.intensity_rgb;
  if (spec.profile) {
    model.has_profile = true;
    model.profile_axis_in_world = spec.profile->axis.normalized();
    model.profile_exponent = spec.profile->exponent;
  }
  return model;
}

const CameraCalibration* CalibrationResult::FindCamera(const std::string& id) const {
  for (const auto& c : cameras) {
    if (c.id == id) return &c;
  }
  return nullptr;
}
const LightCalibration* CalibrationResult::FindLight(const std::string& id) const {
  for (const auto& l : lights) {
    if (l.model.id == id) return &l;
  }
  return nullptr;
}
const FlatCalibration* CalibrationResult::FindFlat(const std::string& camera, const std::string& light,
                                                   const std::string& side) const {
  for (const auto& f : flats) {
    if (f.camera == camera && f.light == light && f.side == side) return &f;
  }
  return nullptr;
}

nlohmann::json CalibrationResult::ToJson() const {
  using nlohmann::json;
  json out;
  out["manifest"] = manifest_file;
  out["grid"] = {{"width", grid.width},   {"height", grid.height}, {"dpi", grid.dpi()},
                 {"pitch_mm", grid.pitch_mm}, {"region_mm", {grid.x0_mm, grid.y1_mm - grid.height * grid.pitch_mm,
                                                         grid.x0_mm + grid.width * grid.pitch_mm, grid.y1_mm}},
                 {"surface_z_mm", surface_z_mm}};
  out["cameras"] = json::array();
  for (const auto& c : cameras) {
    json rotation = json::array();
    for (int r = 0; r < 3; ++r) {
      for (int k = 0; k < 3; ++k) rotation.push_back(c.model.pose.rotation(r, k));
    }
    json camera = {{"id", c.id},
                   {"width", c.model.width},
                   {"height", c.model.height},
                   {"intrinsics", {{"fx", c.model.intrinsics.fx}, {"fy", c.model.intrinsics.fy},
                                   {"cx", c.model.intrinsics.cx}, {"cy", c.model.intrinsics.cy}}},
                   {"distortion", c.model.distortion},
                   {"pose", {{"rotation", rotation}, {"translation_mm", Vector(c.model.pose.translation_mm)}}},
                   {"intrinsics_source", c.intrinsics_source},
                   {"pose_source", c.pose_source},
                   {"board_frames", c.board_frames}};
    camera["reprojection_error_px"] = c.reprojection_error_px ? json(*c.reprojection_error_px) : json(nullptr);
    // Camera pixels per finished-map pixel at the grid's centre (rectification's s; > 1: the
    // footprint pre-filter runs). Sub-pixel structure resolves well from about 2 on.
    const double pitch = c.model.PitchOnPlaneMm(grid.PixelCentreInWorld(grid.width / 2, grid.height / 2, surface_z_mm));
    camera["camera_px_per_map_px"] = pitch > 0.0 ? json(grid.pitch_mm / pitch) : json(nullptr);
    out["cameras"].push_back(camera);
  }
  out["lights"] = json::array();
  for (const auto& l : lights) {
    json light = {{"id", l.model.id},
                  {"type", l.model.type == LightType::kPoint ? "point" : "directional"},
                  {"intensity", Vector(l.model.intensity_rgb)},
                  {"source", l.source},
                  {"placements", l.placements},
                  {"sphere_frames", l.sphere_frames}};
    if (l.model.type == LightType::kPoint) {
      light["position_mm"] = Vector(l.model.position_in_world_mm);
    } else {
      light["direction"] = Vector(l.model.direction_in_world);
    }
    if (l.model.has_profile) {
      light["profile"] = {{"axis", Vector(l.model.profile_axis_in_world)}, {"exponent", l.model.profile_exponent}};
    }
    light["residual"] = l.residual ? json(*l.residual) : json(nullptr);
    if (l.residual) light["residual_unit"] = l.residual_unit;
    if (!l.note.empty()) light["note"] = l.note;
    out["lights"].push_back(light);
  }
  out["dark_frames"] = dark_ambient.dark_frames;
  out["ambient_frames"] = dark_ambient.ambient_frames;
  out["flats"] = json::array();
  for (const auto& f : flats) {
    out["flats"].push_back({{"camera", f.camera}, {"light", f.light}, {"side", f.side}, {"frames", f.frames},
                            {"mean_irradiance", f.irradiance.ChannelMean(0)}});
  }
  if (colour.fitted) {
    json matrix = json::array();
    for (int r = 0; r < 3; ++r) {
      for (int k = 0; k < 3; ++k) matrix.push_back(colour.fit.matrix(r, k));
    }
    out["colour"] = {{"frame", colour.frame},
                     {"applied", colour.applied},
                     {"locator", colour.locator},
                     {"patch_pitch_px", colour.patch_pitch_px},
                     {"ciede2000_cross_validated_mean", colour.fit.delta_e_cross_validated_mean},
                     {"matrix", matrix},
                     {"ciede2000_before_mean", colour.fit.delta_e_before_mean},
                     {"ciede2000_before_max", colour.fit.delta_e_before_max},
                     {"ciede2000_after_mean", colour.fit.delta_e_after_mean},
                     {"ciede2000_after_max", colour.fit.delta_e_after_max}};
    if (!colour.applied) out["colour"]["not_applied_reason"] = colour.not_applied_reason;
  } else {
    out["colour"] = nullptr;
  }
  out["steps"] = json::array();
  for (const auto& s : steps) out["steps"].push_back({{"step", s.step}, {"ran", s.ran}, {"detail", s.detail}});
  out["warnings"] = warnings;
  return out;
}

CalibrationResult Calibrate(const Manifest& manifest, const FrameLoader& load, const CalibrationOptions& options,
                            const ProgressCallback& progress, const std::string& manifest_file) {
  if (!options.Check()) throw std::invalid_argument("CalibrationOptions::Check failed");
  CalibrationResult result;
  result.manifest_file = manifest_file;
  Recorder record(result);
  ReportProgress(progress, "calibrate", 0.0);
  bool has_dark_or_ambient = false;
  for (const auto& f : manifest.frames) {
    has_dark_or_ambient = has_dark_or_ambient || f.role == FrameRole::kDark || f.role == FrameRole::kAmbient;
  }
  if (has_dark_or_ambient) {
    result.dark_ambient = BuildDarkAmbient(manifest, load);
    record.Ran("dark/ambient", std::to_string(result.dark_ambient.dark_frames.size()) + " dark, " +
                                   std::to_string(result.dark_ambient.ambient_frames.size()) + " ambient frame(s)");
  } else {
    record.Skipped("dark/ambient", "no dark or ambient frames");
  }
  ReportProgress(progress, "calibrate", 0.1);
  CalibrateCameras(manifest, load, options, manifest_file, result, record);
  ReportProgress(progress, "calibrate", 0.4);
  ChooseResultGrid(manifest, options, manifest_file, result, record);
  CalibrateLights(manifest, load, options, result, result, record);
  ReportProgress(progress, "calibrate", 0.6);
  CalibrateFlats(manifest, load, options, result, record);
  ReportProgress(progress, "calibrate", 0.8);
  CalibrateColour(manifest, load, options, result, record);
  ReportProgress(progress, "calibrate", 1.0);
  return result;
}

CalibrationResult Calibrate(const Capture& capture, const CalibrationOptions& options, const ProgressCallback& progress) {
  return Calibrate(
      capture.manifest(), [&capture](std::size_t index) { return capture.LoadFrame(index); }, options, progress,
      (capture.folder() / "capture.json").string());
}

Stack BuildStack(const Manifest& manifest, const FrameLoader& load, const CalibrationResult& calibration,
                 const CalibrationOptions& options, const ProgressCallback& progress, const Image& surface_z_mm) {
  const auto sample_indices = FramesWith(manifest, FrameRole::kSample, nullptr, nullptr, &options.side);
  if (sample_indices.empty()) {
    throw InputError(calibration.manifest_file, "/frames", "sample frames of side \"" + options.side + "\"");
  }
  Stack stack;
  stack.side = options.side;
  stack.grid = calibration.grid;
  std::map<std::string, int> view_of_camera, light_of_id;
  std::map<std::string, RectificationMap> maps;
  const bool colour = options.apply_colour_correction && calibration.colour.applied;
  const Eigen::Matrix3f colour_matrix = calibration.colour.fit.matrix.cast<float>();
  for (std::size_t n = 0; n < sample_indices.size(); ++n) {
    const std::size_t index = sample_indices[n];
    const FrameSpec& spec = manifest.frames[index];
    const CameraCalibration* camera = calibration.FindCamera(spec.camera);
    const LightCalibration* light = spec.light ? calibration.FindLight(*spec.light) : nullptr;
    if (!camera || !light) {
      throw InputError(spec.file, FrameField(index), "a sample frame of a calibrated camera under one light");
    }
    if (!view_of_camera.count(spec.camera)) {
      view_of_camera[spec.camera] = static_cast<int>(stack.views.size());
      stack.views.push_back({spec.camera, camera->model.CentreInWorld()});
      maps.emplace(spec.camera, surface_z_mm.empty()
                                    ? BuildRectificationMap(camera->model, calibration.grid, calibration.surface_z_mm)
                                    : BuildRectificationMap(camera->model, calibration.grid, surface_z_mm));
    }
    if (!light_of_id.count(*spec.light)) {
      light_of_id[*spec.light] = static_cast<int>(stack.lights.size());
      stack.lights.push_back(light->model);
    }
    const DecodedFrame frame = LoadCorrected(manifest, load, calibration.dark_ambient, index);
    RectifiedFrame rectified = Rectify(frame, maps.at(spec.camera));
    Observation observation;
    observation.view = view_of_camera[spec.camera];
    observation.light = light_of_id[*spec.light];
    // Frame units -> f * cos * E_rel: divide by exposure and the light's intensity per channel, then
    // take the camera's RGB to linear sRGB.
    Image& rgb = rectified.rgb;
    NormaliseObservationRgb(rgb, spec.exposure_s, light->model.intensity_rgb, colour, colour_matrix);
    observation.rgb = std::move(rgb);
    observation.flags = std::move(rectified.flags);
    if (const FlatCalibration* flat = calibration.FindFlat(spec.camera, *spec.light, spec.side)) {
      observation.irradiance = flat->irradiance;
    }
    stack.observations.push_back(std::move(observation));
    ReportProgress(progress, "stack", static_cast<double>(n + 1) / sample_indices.size());
  }
  LogInfo() << "stack (" << options.side << "): " << stack.observations.size() << " observations, "
            << stack.views.size() << " view(s), " << stack.lights.size() << " light(s) on " << stack.grid.width
            << " x " << stack.grid.height << " px at " << stack.grid.dpi() << " dpi";
  return stack;
}

Stack BuildStack(const Capture& capture, const CalibrationResult& calibration, const CalibrationOptions& options,
                 const ProgressCallback& progress, const Image& surface_z_mm) {
  return BuildStack(
      capture.manifest(), [&capture](std::size_t index) { return capture.LoadFrame(index); }, calibration, options,
      progress, surface_z_mm);
}

}  // namespace u3mscan
