#pragma once
// The synthetic scanner's output: a capture folder exactly as a physical scanner would write it
// (docs/capture-format.md) plus the ground truth beside it:
//
//   DIR/capture/capture.json          the manifest (capture/manifest.h WriteManifest)
//   DIR/capture/frames/<camera>/...   sample and ambient frames
//   DIR/capture/calibration/<camera>/ dark, flat, board, sphere, chart, backlight frames
//   DIR/truth/truth.json              the scene's truth (truth_writer.h) + "rig": geometry, sensor,
//                                     calibration targets, units
//   DIR/truth/<map>.exr               the scene's maps (truth_writer.h)
//
// Frames are rendered, exposed and written one at a time, so a 36-megapixel capture needs memory
// for one frame (plus the scene and one camera's ray hits), not for all of them. Atomic: all of
// it is written into a hidden sibling folder that is renamed to DIR at the end; a failure removes
// it and leaves no DIR.

#include <cstdint>
#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <optional>
#include <set>
#include <string>

#include "capture/manifest.h"
#include "core/progress.h"
#include "datasets_synthetic/rig.h"
#include "datasets_synthetic/scene.h"

namespace u3mscan::synthetic {

enum class FrameFormat {
  kDng,   // RGGB Bayer mosaic, 16-bit DNG with the sensor's black and white level (libraw decodes it)
  kTiff,  // 16-bit RGB TIFF of the decoded value (black subtracted, 65535 = white level)
  kExr,   // float RGB EXR of the decoded value (1.0 = white level), same quantisation as the sensor
};
const char* FrameFormatName(FrameFormat format);
// "dng", "tiff"/"tif", "exr"; nullopt otherwise.
std::optional<FrameFormat> FrameFormatFromName(const std::string& name);

// Writes the scene's truth (maps and truth.json) into a folder, with `extra` (the capture
// writer's "rig" section: cameras, lights, sensor, targets, units) added to truth.json. Default:
// WriteTruth of truth_writer.h. Tests pass their own to simulate failures.
using TruthWriter = std::function<void(const SceneTruth& scene, const nlohmann::json& extra,
                                       const std::filesystem::path& truth_dir)>;

// Every calibration role the synthetic scanner can render (docs/capture-format.md, "Frame roles").
std::set<FrameRole> AllCalibrationRoles();
// "dark,flat" -> {kDark, kFlat}; "all" -> AllCalibrationRoles(). Throws InputError naming `option`
// for a name that is not a calibration role (sample and ambient frames are always written).
std::set<FrameRole> CalibrationRolesFromList(const std::string& list, const std::string& option);

struct CaptureOptions {
  FrameFormat format = FrameFormat::kDng;
  bool calibration_frames = true;  // false: sample and ambient frames only, whatever calibration_roles says
  // With calibration_frames, the roles written (default: all of them). {kDark, kFlat} is a scanner
  // whose geometry comes from the manifest and which takes a flat field per light: the flats
  // measure the irradiance, the lens vignetting included, and nothing else is calibrated.
  // Backlight frames are written only for scenes with holes, whatever is asked.
  std::set<FrameRole> calibration_roles = AllCalibrationRoles();
  bool write_pose = true;          // false: cameras without pose, calibration must find it (board)
  // sample.thickness_mm = the scene's highest point, as a thickness gauge reads it: the pipeline
  // makes its maps on that plane (capture/rectification.h, SampleSurfaceZMm). false: left out, the
  // maps lie on z = 0 (a scanner that does not know how thick the sample is).
  bool write_thickness = true;
  // Rays per camera pixel along each axis for the sample frames (RenderOptions::supersample).
  int supersample = 1;
  std::string scanner_software = "u3mscan";
  ProgressCallback progress;
  bool Check() const { return supersample >= 1; }
};

struct CaptureStats {
  int frames = 0;
  double megapixels_rendered = 0;  // camera pixels rendered, summed over frames
  double render_seconds = 0;       // ray tracing, shading and the sensor model, not file writing
  double total_seconds = 0;
  double MegapixelsPerSecond() const { return render_seconds > 0 ? megapixels_rendered / render_seconds : 0; }
};

// Renders and writes DIR. `out_dir` must not exist, or be an empty folder. Throws InputError
// naming out_dir when it cannot be used; any failure leaves no DIR behind.
CaptureStats WriteSyntheticCapture(const SceneTruth& scene, const Rig& rig, const CaptureOptions& options,
                                   const std::filesystem::path& out_dir, const TruthWriter& truth_writer = {});
// The same, rendering `render_scene` (a finer sampling of the fabric, OversampledSceneOptions)
// and writing `truth` (its AreaAverageScene on the output grid) as the truth; the manifest's
// output grid is truth's. Both must cover the same rectangle (std::invalid_argument otherwise).
CaptureStats WriteSyntheticCapture(const SceneTruth& render_scene, const SceneTruth& truth, const Rig& rig,
                                   const CaptureOptions& options, const std::filesystem::path& out_dir,
                                   const TruthWriter& truth_writer = {});

// Relative paths of the folders inside DIR.
inline constexpr const char* kCaptureSubdir = "capture";
inline constexpr const char* kTruthSubdir = "truth";
inline constexpr const char* kTruthFileName = "truth.json";

}  // namespace u3mscan::synthetic
