#pragma once
// Calibrate: every calibration step a capture calls for, in order (dark/ambient, cameras, grid,
// lights, flat fields, colour), each running only when the capture holds the frames it takes and
// saying in CalibrationResult::steps what it did or why it was skipped. BuildStack then turns one
// side's sample frames into the Stack (core/stack.h) that reconstruction and fitting consume.
//
// Bad calibration frames (board, sphere or chart not found, a flat darker than its sample frame)
// give a message naming the frame; the step falls back to the manifest where it can (recorded in
// `warnings`), and the capture is refused with InputError where it cannot (a camera with neither
// a pose in the manifest nor a usable board frame).

#include <Eigen/Core>
#include <array>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "capture/calibration_frames.h"
#include "capture/camera_model.h"
#include "capture/colour_calibration.h"
#include "capture/dark_ambient.h"
#include "capture/light_calibration.h"
#include "capture/manifest.h"
#include "core/image.h"
#include "core/progress.h"
#include "core/stack.h"

namespace u3mscan {

class Capture;

struct CalibrationOptions {
  std::string side = "front";            // the side BuildStack builds
  std::optional<double> dpi;             // overrides the manifest's output.dpi
  std::optional<std::array<double, 4>> region_mm;  // overrides output.region_mm
  bool calibrate_intrinsics = true;      // from board frames, when a camera has enough
  int min_board_frames_for_intrinsics = 3;
  int min_board_corners = 6;
  bool use_mcc = true;                   // try cv::mcc before the known chart layout
  ChartLayout chart_layout;              // where the chart lies when mcc finds none
  bool apply_colour_correction = true;   // in BuildStack, when a chart was fitted
  // A chart whose patches a 3x3 matrix cannot bring within this mean CIEDE2000 of the reference
  // is not a chart (a blank frame, a wrong layout): "chart not found".
  double max_chart_delta_e = 5.0;
  // A chart whose patches lie fewer camera pixels apart than this is too small to trust: the
  // sampled centre of a patch (half its pitch) keeps only ~0.15 pitch from the patch's edge, and
  // the locator (mcc's box, measured off by up to 1.2 px on a 48 px frame) plus one pixel of
  // anti-aliasing must fit in that margin: 0.15 * 10 px = 1.5 px. Measured on the synthetic
  // scanner (distant rig, plain): pitch 6.2 px (48 px frame) gave a matrix with gains of 1.05-1.25
  // that took the albedo from dE 2.86 to 6.41; 8.2 px (64 px) from 2.94 to 3.71; 10.3 px (80 px)
  // and more left it unchanged (docs/calibration.md). The matrix is then not applied (identity).
  double min_chart_patch_pitch_px = 10.0;
  double min_flat_cos = 0.05;            // flat pixels with grazing light are not measured
  // Mirror spheres found in their frames rest on the sample plane (centre z = radius), or sit at
  // the height of the manifest's centre_mm when it gives one; false: the height is fitted too.
  bool sphere_on_known_height = true;
  LightFitOptions light_fit;             // highlight accuracy, manifest prior for point lights
  // Fit all lights and the sphere placements they share together (light_joint_fit.h); false:
  // each light alone on its own frames' sphere centres.
  bool joint_light_fit = true;
  bool Check() const;
};

struct StepReport {
  std::string step;    // "dark/ambient", "camera top", "grid", "light L1", "flat top/L1/front", "colour"
  bool ran = false;
  std::string detail;  // what it did, or why it was skipped
};

struct CameraCalibration {
  std::string id;
  CameraModel model;
  std::string intrinsics_source = "manifest";  // or "board frames"
  std::string pose_source = "manifest";        // or "board frame <file>"
  std::optional<double> reprojection_error_px;  // of the pose (or intrinsics fit) on board corners
  std::vector<std::string> board_frames;        // used
};

struct LightCalibration {
  LightModel model;
  std::string source = "manifest";  // or "mirror sphere", or "mirror sphere + flat" (one placement, light_from_plane.h)
  int placements = 0;
  std::optional<double> residual;   // deg (directional) or mm (point); see LightFit
  std::string residual_unit;
  std::string note;
  std::vector<std::string> sphere_frames;  // used
};

struct FlatCalibration {
  std::string camera, light, side;
  std::vector<std::string> frames;  // averaged
  Image irradiance;                 // on the grid, units of LightModel::RelativeIrradianceAt
};

struct ColourCalibration {
  bool fitted = false;
  // Applied by BuildStack only when the chart is large enough to trust (patch pitch of at least
  // CalibrationOptions::min_chart_patch_pitch_px) and the matrix brings colours it was not fitted
  // to closer to the reference (leave-one-out mean CIEDE2000 < before): a camera already in sRGB
  // gains nothing but noise from a 3x3 fit. Otherwise the camera's RGB is used as is (identity).
  bool applied = false;
  std::string not_applied_reason;  // empty when applied
  std::string frame;
  std::string locator;  // "mcc" or "known layout"
  double patch_pitch_px = 0;  // distance between neighbouring patch centres in the frame
  ColourFit fit;
};

struct CalibrationResult {
  std::string manifest_file;
  MetricGrid grid;
  // The plane the grid lies in for the sample's frames (mm, SampleSurfaceZMm: the sample's face);
  // the board, flats' targets and chart lie on z = 0.
  double surface_z_mm = 0.0;
  std::vector<CameraCalibration> cameras;
  std::vector<LightCalibration> lights;  // manifest order
  DarkAmbient dark_ambient;
  std::vector<FlatCalibration> flats;
  ColourCalibration colour;
  std::vector<StepReport> steps;
  std::vector<std::string> warnings;  // bad calibration input that led to a fallback

  const CameraCalibration* FindCamera(const std::string& id) const;
  const LightCalibration* FindLight(const std::string& id) const;
  const FlatCalibration* FindFlat(const std::string& camera, const std::string& light, const std::string& side) const;
  // Everything above but the images: the content of calibration.json.
  nlohmann::json ToJson() const;
};

CalibrationResult Calibrate(const Capture& capture, const CalibrationOptions& options,
                            const ProgressCallback& progress = {});
// The same on a manifest and any frame source (tests: frames made in memory).
CalibrationResult Calibrate(const Manifest& manifest, const FrameLoader& load, const CalibrationOptions& options,
                            const ProgressCallback& progress = {}, const std::string& manifest_file = "capture.json");

// One side's sample frames on the grid: dark/ambient taken away, rectified, divided by exposure and
// the light's intensity, colour-corrected, flagged; measured irradiance where flats were taken.
// Throws InputError when the side has no sample frames.
// The grid lies on the plane z = calibration.surface_z_mm; with `surface_z_mm` (1 plane of the
// grid's size, mm, world z: the relief, pipeline/relief_registration.h) every grid pixel is taken
// at its own height instead, which registers a tilted view on the relief.
Stack BuildStack(const Capture& capture, const CalibrationResult& calibration, const CalibrationOptions& options,
                 const ProgressCallback& progress = {}, const Image& surface_z_mm = Image());
Stack BuildStack(const Manifest& manifest, const FrameLoader& load, const CalibrationResult& calibration,
                 const CalibrationOptions& options, const ProgressCallback& progress = {},
                 const Image& surface_z_mm = Image());

// The manifest's description of a light as a LightModel.
LightModel LightModelFromSpec(const LightSpec& spec);

}  // namespace u3mscan
