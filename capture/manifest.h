#pragma once
// Manifest: the typed content of a capture folder's capture.json (format "u3m-capture/1"), the
// project's public contract with scanner vendors (docs/capture-format.md). Lengths in mm, angles in
// degrees, times in seconds; poses are world_from_camera.
//
// ReadManifest checks everything the contract says and throws InputError naming the file, the JSON
// pointer and what was expected. WriteManifest is what the synthetic scanner (and tests) use to
// produce capture folders.

#include <Eigen/Core>
#include <array>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace u3mscan {

inline constexpr const char* kCaptureFormat = "u3m-capture/1";

struct ScannerInfo {
  std::string vendor;
  std::string model;
  std::string serial;
  std::string software;
  nlohmann::json extra = nlohmann::json::object();  // vendor keys, kept as they are
};

struct SampleInfo {
  std::string name;
  std::string description;
  std::optional<double> thickness_mm;
  std::optional<double> weight_gsm;
  nlohmann::json extra = nlohmann::json::object();  // vendor keys, kept as they are
};

struct OutputSpec {
  std::optional<double> dpi;
  std::optional<std::array<double, 4>> region_mm;  // [x0, y0, x1, y1] on the sample plane
};

struct CameraIntrinsics {
  double fx = 0, fy = 0, cx = 0, cy = 0;  // pixels, OpenCV convention (pixel centres integer)
};

struct CameraPose {
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();  // world_from_camera
  Eigen::Vector3d translation_mm = Eigen::Vector3d::Zero(); // camera centre in world, mm
};

// Levels in the frame file's own code values: raw ADU for RAW files (overrides the file's own
// black/white), 0..65535 for 16-bit TIFF/PNG, stored values for EXR. A linear value becomes
// (v - black_level) / (white_level - black_level); v >= white_level is saturated.
struct SensorResponse {
  double black_level = 0.0;
  double white_level = 65535.0;
};

struct CameraSpec {
  std::string id;
  int width = 0;
  int height = 0;
  CameraIntrinsics intrinsics;
  std::array<double, 5> distortion{};  // k1, k2, p1, p2, k3
  std::optional<CameraPose> pose;      // absent: found from a `board` frame
  std::optional<SensorResponse> response;
  // RAW white-balance multipliers (R, G, B) applied to the sensor channels before demosaicing.
  // Absent: the camera's as-shot white balance ("camera white balance unless the manifest says
  // otherwise"); [1, 1, 1]: raw sensor colour. JSON key `white_balance` (a project extension).
  std::optional<std::array<double, 3>> white_balance;
  nlohmann::json extra = nlohmann::json::object();  // vendor keys, kept as they are
};

struct LightProfile {
  Eigen::Vector3d axis = -Eigen::Vector3d::UnitZ();  // unit, from the light toward the scene
  double exponent = 1.0;                             // intensity ~ cos^exponent(angle to axis)
};

enum class ManifestLightType { kPoint, kDirectional };

struct LightSpec {
  std::string id;
  ManifestLightType type = ManifestLightType::kDirectional;
  std::optional<Eigen::Vector3d> position_mm;  // point lights
  std::optional<Eigen::Vector3d> direction;    // directional: unit, sample -> light
  Eigen::Vector3d intensity_rgb = Eigen::Vector3d::Ones();
  std::optional<LightProfile> profile;  // point lights only
  nlohmann::json extra = nlohmann::json::object();  // vendor keys, kept as they are
};

enum class FrameRole { kSample, kAmbient, kDark, kFlat, kBoard, kSphere, kChart, kBacklight };
const char* FrameRoleName(FrameRole role);
// "sample" -> kSample, ...; nullopt for a name the contract does not know.
std::optional<FrameRole> FrameRoleFromName(const std::string& name);

struct FrameSpec {
  std::string file;              // relative to the capture folder, '/' separators
  std::string camera;            // CameraSpec::id
  std::optional<std::string> light;  // LightSpec::id; nullopt = all lights off
  std::string side = "front";    // "front" or "back"
  double exposure_s = 0.0;
  FrameRole role = FrameRole::kSample;
  nlohmann::json extra = nlohmann::json::object();  // vendor keys, kept as they are
};

struct BoardTarget {
  int squares_x = 0;
  int squares_y = 0;
  double square_mm = 0.0;
  double marker_mm = 0.0;
  std::string dictionary;  // OpenCV name, e.g. "DICT_5X5_100"
};
struct WhiteTarget {
  double reflectance = 1.0;
};
struct SphereTarget {
  double radius_mm = 0.0;
  std::optional<Eigen::Vector3d> center_mm;
};
struct ChartTarget {
  std::string type;  // e.g. "macbeth24"
};

struct Targets {
  std::optional<BoardTarget> board;
  std::optional<WhiteTarget> white;
  std::optional<SphereTarget> sphere;
  std::optional<ChartTarget> chart;
  nlohmann::json extra = nlohmann::json::object();  // vendor target kinds, kept as they are
};

struct Manifest {
  std::string format = kCaptureFormat;
  ScannerInfo scanner;
  SampleInfo sample;
  OutputSpec output;
  std::vector<CameraSpec> cameras;
  std::vector<LightSpec> lights;
  std::vector<FrameSpec> frames;
  Targets targets;
  // Vendor keys the contract does not name, kept so a rewrite loses nothing.
  nlohmann::json extra = nlohmann::json::object();

  const CameraSpec* FindCamera(const std::string& id) const;
  const LightSpec* FindLight(const std::string& id) const;
};

inline constexpr const char* kManifestFileName = "capture.json";

struct FrameHeader;  // capture/frame_decoder.h

// Parses and checks capture.json in `capture_dir` (or a capture.json path): everything
// ParseManifest checks, plus frame files that exist inside the folder (no symlink escapes) and
// frame headers whose size equals their camera's width x height (headers only, no decoding).
// Throws InputError(capture.json path, JSON pointer, expectation) on the first violation.
// `headers` (optional): the header read of each frame, in the manifest's order, so that a reader
// of the frames need not open them again to learn it (Capture::Open).
Manifest ReadManifest(const std::filesystem::path& capture_dir_or_file, std::vector<FrameHeader>* headers = nullptr);
// Parses and checks an in-memory JSON text; `source_name` (the file) is used in messages.
// Checks types, ranges, ids, references, roles and targets; does not touch the file system.
Manifest ParseManifest(const std::string& json_text, const std::string& source_name);
// The JSON a ParseManifest of it returns unchanged (vendor keys included).
nlohmann::json ManifestToJson(const Manifest& manifest);
// Checks `manifest` as ParseManifest would (throws InputError naming the target file on a
// violation, writing nothing), creates `capture_dir` if needed and writes capture.json into it
// atomically (temporary file in the same folder, then rename). Frame files are not checked, so
// a writer may write the manifest before or after its frames.
void WriteManifest(const Manifest& manifest, const std::filesystem::path& capture_dir);

}  // namespace u3mscan
