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
};

struct SampleInfo {
  std::string name;
  std::string description;
  std::optional<double> thickness_mm;
  std::optional<double> weight_gsm;
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

struct SensorResponse {
  double black_level = 0.0;
  double white_level = 1.0;
};

struct CameraSpec {
  std::string id;
  int width = 0;
  int height = 0;
  CameraIntrinsics intrinsics;
  std::array<double, 5> distortion{};  // k1, k2, p1, p2, k3
  std::optional<CameraPose> pose;      // absent: found from a `board` frame
  std::optional<SensorResponse> response;
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
  std::optional<LightProfile> profile;
};

enum class FrameRole { kSample, kAmbient, kDark, kFlat, kBoard, kSphere, kChart, kBacklight };
const char* FrameRoleName(FrameRole role);

struct FrameSpec {
  std::string file;              // relative to the capture folder, '/' separators
  std::string camera;            // CameraSpec::id
  std::optional<std::string> light;  // LightSpec::id; nullopt = all lights off
  std::string side = "front";    // "front" or "back"
  double exposure_s = 0.0;
  FrameRole role = FrameRole::kSample;
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

// Parses and checks capture.json in `capture_dir` (or a capture.json path). Checks include frame
// files that exist, ids that resolve, lights with position or direction, positive exposures,
// frames of one camera with the camera's size. Throws InputError on the first violation.
Manifest ReadManifest(const std::filesystem::path& capture_dir_or_file);
// Parses from an in-memory JSON text; `source_name` is used in messages. Does not check files.
Manifest ParseManifest(const std::string& json_text, const std::string& source_name);
nlohmann::json ManifestToJson(const Manifest& manifest);
// Writes capture.json into `capture_dir` atomically (temporary file, then rename).
void WriteManifest(const Manifest& manifest, const std::filesystem::path& capture_dir);

}  // namespace u3mscan
