#include "capture/manifest.h"

#include <Eigen/LU>
#include <cmath>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <system_error>

#include "capture/frame_decoder.h"
#include "core/error.h"

namespace u3mscan {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// Tolerances of the contract's geometric checks (unitless).
constexpr double kUnitVectorTolerance = 1e-3;  // |direction| and |axis| must be 1 within this
constexpr double kRotationTolerance = 1e-4;    // R^T R = I and det R = 1 within this
constexpr int kMaxCameraSide = 1 << 16;        // pixels; larger is a typo or a hostile file

std::string EscapePointerToken(const std::string& token) {
  std::string out;
  for (char c : token) {
    if (c == '~') {
      out += "~0";
    } else if (c == '/') {
      out += "~1";
    } else {
      out += c;
    }
  }
  return out;
}

std::string TypeName(const json& value) {
  if (value.is_null()) return "null";
  if (value.is_boolean()) return "a boolean";
  if (value.is_number()) return "a number (" + value.dump() + ")";
  if (value.is_string()) return "a string (" + value.dump() + ")";
  if (value.is_array()) return "an array";
  return "an object";
}

// A position in the manifest: the source file and a JSON pointer. Every check throws through
// Fail(), so every message has the same three parts.
class Node {
 public:
  Node(const json& value, const std::string& file, std::string pointer)
      : value_(value), file_(file), pointer_(std::move(pointer)) {}

  const json& value() const { return value_; }
  const std::string& pointer() const { return pointer_; }
  const std::string& file() const { return file_; }

  [[noreturn]] void Fail(const std::string& expected) const {
    throw InputError(file_, pointer_.empty() ? "/" : pointer_, expected);
  }
  [[noreturn]] void FailGot(const std::string& expected) const {
    Fail(expected + ", got " + TypeName(value_));
  }

  bool Has(const std::string& key) const { return value_.contains(key); }
  Node Child(const std::string& key) const {
    return Node(value_.at(key), file_, pointer_ + "/" + EscapePointerToken(key));
  }
  Node Child(std::size_t index) const {
    return Node(value_.at(index), file_, pointer_ + "/" + std::to_string(index));
  }
  // A key that must be present. The pointer names the missing key itself.
  Node Required(const std::string& key, const std::string& expected) const {
    if (!value_.contains(key)) {
      throw InputError(file_, pointer_ + "/" + EscapePointerToken(key), "a required key: " + expected);
    }
    return Child(key);
  }

  void ExpectObject(const std::string& what) const {
    if (!value_.is_object()) FailGot(what + " (a JSON object)");
  }
  void ExpectArray(const std::string& what) const {
    if (!value_.is_array()) FailGot(what + " (a JSON array)");
  }
  std::string String(const std::string& what) const {
    if (!value_.is_string()) FailGot(what + " (a string)");
    return value_.get<std::string>();
  }
  std::string NonEmptyString(const std::string& what) const {
    std::string s = String(what);
    if (s.empty()) Fail(what + " (a non-empty string)");
    return s;
  }
  double Number(const std::string& what) const {
    if (!value_.is_number()) FailGot(what + " (a number)");
    const double v = value_.get<double>();
    if (!std::isfinite(v)) Fail(what + " (a finite number)");
    return v;
  }
  double Positive(const std::string& what) const {
    const double v = Number(what);
    if (!(v > 0.0)) Fail(what + " (a number > 0), got " + value_.dump());
    return v;
  }
  double NonNegative(const std::string& what) const {
    const double v = Number(what);
    if (v < 0.0) Fail(what + " (a number >= 0), got " + value_.dump());
    return v;
  }
  int Integer(const std::string& what, int min_value, int max_value) const {
    const double v = Number(what);
    if (v != std::floor(v) || v < min_value || v > max_value) {
      Fail(what + " (an integer in [" + std::to_string(min_value) + ", " + std::to_string(max_value) +
           "]), got " + value_.dump());
    }
    return static_cast<int>(v);
  }
  template <std::size_t N>
  std::array<double, N> NumberArray(const std::string& what) const {
    if (!value_.is_array() || value_.size() != N) FailGot(what + " (an array of " + std::to_string(N) + " numbers)");
    std::array<double, N> out{};
    for (std::size_t i = 0; i < N; ++i) out[i] = Child(i).Number(what + " element");
    return out;
  }
  Eigen::Vector3d Vector3(const std::string& what) const {
    const auto a = NumberArray<3>(what);
    return {a[0], a[1], a[2]};
  }
  Eigen::Vector3d UnitVector3(const std::string& what) const {
    const Eigen::Vector3d v = Vector3(what);
    if (std::abs(v.norm() - 1.0) > kUnitVectorTolerance) {
      std::ostringstream s;
      s << what << " (a unit vector, |v| = 1 within " << kUnitVectorTolerance << "), got |v| = " << v.norm();
      Fail(s.str());
    }
    return v;
  }

  // Keys not in `known` go to `extra` (vendor keys), or are refused when `closed`.
  void CollectExtra(const std::set<std::string>& known, json* extra, bool closed) const {
    for (auto it = value_.begin(); it != value_.end(); ++it) {
      if (known.count(it.key())) continue;
      if (closed) {
        std::string list;
        for (const auto& k : known) list += (list.empty() ? "" : ", ") + k;
        throw InputError(file_, pointer_ + "/" + EscapePointerToken(it.key()),
                         "one of the keys {" + list + "}; this object takes no other key");
      }
      (*extra)[it.key()] = it.value();
    }
  }

 private:
  const json& value_;
  const std::string& file_;
  std::string pointer_;
};

std::optional<std::string> OptionalString(const Node& parent, const std::string& key, const std::string& what) {
  if (!parent.Has(key)) return std::nullopt;
  return parent.Child(key).String(what);
}

ScannerInfo ParseScanner(const Node& node) {
  node.ExpectObject("scanner information {vendor, model, serial, software}");
  ScannerInfo s;
  s.vendor = OptionalString(node, "vendor", "the scanner vendor").value_or("");
  s.model = OptionalString(node, "model", "the scanner model").value_or("");
  s.serial = OptionalString(node, "serial", "the scanner serial number").value_or("");
  s.software = OptionalString(node, "software", "the scanner software").value_or("");
  node.CollectExtra({"vendor", "model", "serial", "software"}, &s.extra, false);
  return s;
}

SampleInfo ParseSample(const Node& node) {
  node.ExpectObject("sample information {name, description}");
  SampleInfo s;
  s.name = OptionalString(node, "name", "the sample name").value_or("");
  s.description = OptionalString(node, "description", "the sample description").value_or("");
  if (node.Has("thickness_mm")) s.thickness_mm = node.Child("thickness_mm").Positive("a thickness in mm");
  if (node.Has("weight_gsm")) s.weight_gsm = node.Child("weight_gsm").Positive("a weight in g/m^2");
  node.CollectExtra({"name", "description", "thickness_mm", "weight_gsm"}, &s.extra, false);
  return s;
}

OutputSpec ParseOutput(const Node& node) {
  node.ExpectObject("output settings {dpi, region_mm}");
  OutputSpec out;
  if (node.Has("dpi")) out.dpi = node.Child("dpi").Positive("the resolution of the finished maps in dots per inch");
  if (node.Has("region_mm")) {
    const Node r = node.Child("region_mm");
    const auto a = r.NumberArray<4>("the rectangle [x0, y0, x1, y1] in mm");
    if (!(a[2] > a[0] && a[3] > a[1])) r.Fail("a rectangle [x0, y0, x1, y1] with x1 > x0 and y1 > y0");
    out.region_mm = a;
  }
  json ignored;
  node.CollectExtra({"dpi", "region_mm"}, &ignored, true);
  return out;
}

CameraPose ParsePose(const Node& node) {
  node.ExpectObject("a pose {rotation, translation_mm} (world_from_camera)");
  CameraPose pose;
  const Node r = node.Required("rotation", "a 3x3 rotation matrix, row-major");
  const json& rv = r.value();
  if (rv.is_array() && rv.size() == 3 && rv[0].is_array()) {
    for (int i = 0; i < 3; ++i) {
      const auto row = r.Child(static_cast<std::size_t>(i)).NumberArray<3>("a row of 3 numbers of the rotation");
      for (int j = 0; j < 3; ++j) pose.rotation(i, j) = row[j];
    }
  } else {
    const auto flat = r.NumberArray<9>("a 3x3 rotation matrix (3 rows of 3 numbers, or 9 numbers row-major)");
    for (int i = 0; i < 9; ++i) pose.rotation(i / 3, i % 3) = flat[i];
  }
  const Eigen::Matrix3d& R = pose.rotation;
  const double orthogonality = (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (orthogonality > kRotationTolerance || std::abs(R.determinant() - 1.0) > kRotationTolerance) {
    r.Fail("a proper rotation matrix (orthonormal, determinant +1)");
  }
  pose.translation_mm = node.Required("translation_mm", "the camera centre in world, mm").Vector3("the camera centre [x, y, z] in mm");
  json ignored;
  node.CollectExtra({"rotation", "translation_mm"}, &ignored, true);
  return pose;
}

CameraSpec ParseCamera(const Node& node) {
  node.ExpectObject("a camera {id, width, height, intrinsics, distortion, pose?, response?}");
  CameraSpec c;
  c.id = node.Required("id", "the camera id").NonEmptyString("a camera id");
  c.width = node.Required("width", "the image width in pixels").Integer("an image width in pixels", 1, kMaxCameraSide);
  c.height = node.Required("height", "the image height in pixels").Integer("an image height in pixels", 1, kMaxCameraSide);
  const Node in = node.Required("intrinsics", "{fx, fy, cx, cy} in pixels");
  in.ExpectObject("intrinsics {fx, fy, cx, cy} in pixels");
  c.intrinsics.fx = in.Required("fx", "focal length in pixels").Positive("a focal length in pixels");
  c.intrinsics.fy = in.Required("fy", "focal length in pixels").Positive("a focal length in pixels");
  c.intrinsics.cx = in.Required("cx", "principal point x in pixels").Number("a principal point x in pixels");
  c.intrinsics.cy = in.Required("cy", "principal point y in pixels").Number("a principal point y in pixels");
  json ignored;
  in.CollectExtra({"fx", "fy", "cx", "cy"}, &ignored, true);
  c.distortion = node.Required("distortion", "[k1, k2, p1, p2, k3]").NumberArray<5>("distortion [k1, k2, p1, p2, k3]");
  if (node.Has("pose")) c.pose = ParsePose(node.Child("pose"));
  if (node.Has("response")) {
    const Node r = node.Child("response");
    r.ExpectObject("a sensor response {black_level, white_level}");
    SensorResponse resp;
    resp.black_level = r.Required("black_level", "the black level in code values").NonNegative("a black level in code values");
    const Node w = r.Required("white_level", "the white level in code values");
    resp.white_level = w.Positive("a white level in code values");
    if (!(resp.white_level > resp.black_level)) {
      w.Fail("a white level above the black level (" + r.Child("black_level").value().dump() + ")");
    }
    r.CollectExtra({"black_level", "white_level"}, &ignored, true);
    c.response = resp;
  }
  if (node.Has("white_balance")) {
    const Node wb = node.Child("white_balance");
    const auto m = wb.NumberArray<3>("RAW white-balance multipliers [r, g, b]");
    for (std::size_t i = 0; i < 3; ++i) {
      if (!(m[i] > 0.0)) wb.Child(i).Fail("a white-balance multiplier > 0");
    }
    c.white_balance = m;
  }
  node.CollectExtra({"id", "width", "height", "intrinsics", "distortion", "pose", "response", "white_balance"},
                    &c.extra, false);
  return c;
}

LightSpec ParseLight(const Node& node) {
  node.ExpectObject("a light {id, type, position_mm or direction, intensity, profile?}");
  LightSpec l;
  l.id = node.Required("id", "the light id").NonEmptyString("a light id");
  const Node type = node.Required("type", "\"point\" or \"directional\"");
  const std::string t = type.String("a light type, \"point\" or \"directional\"");
  if (t == "point") {
    l.type = ManifestLightType::kPoint;
  } else if (t == "directional") {
    l.type = ManifestLightType::kDirectional;
  } else {
    type.Fail("a light type, \"point\" or \"directional\", got \"" + t + "\"");
  }
  const bool has_pos = node.Has("position_mm"), has_dir = node.Has("direction");
  if (l.type == ManifestLightType::kPoint) {
    if (has_dir) node.Child("direction").Fail("no direction for a point light (it has position_mm)");
    if (!has_pos) node.Required("position_mm", "the position [x, y, z] in mm of a point light");
    l.position_mm = node.Child("position_mm").Vector3("a light position [x, y, z] in mm");
  } else {
    if (has_pos) node.Child("position_mm").Fail("no position_mm for a directional light (it has direction)");
    if (!has_dir) node.Required("direction", "the unit vector from the sample toward a directional light");
    l.direction = node.Child("direction").UnitVector3("a direction from the sample toward the light");
  }
  const Node in = node.Required("intensity", "[r, g, b] relative radiant intensity");
  const auto rgb = in.NumberArray<3>("an intensity [r, g, b]");
  for (std::size_t i = 0; i < 3; ++i) {
    if (!(rgb[i] > 0.0)) in.Child(i).Fail("an intensity > 0 (frames are divided by it)");
  }
  l.intensity_rgb = {rgb[0], rgb[1], rgb[2]};
  if (node.Has("profile")) {
    const Node p = node.Child("profile");
    if (l.type != ManifestLightType::kPoint) p.Fail("no emitter profile for a directional light");
    p.ExpectObject("an emitter profile {axis, exponent}");
    LightProfile profile;
    profile.axis = p.Required("axis", "the emitter axis, a unit vector from the light").UnitVector3("an emitter axis");
    profile.exponent = p.Required("exponent", "the cos^n exponent").NonNegative("a profile exponent");
    json ignored;
    p.CollectExtra({"axis", "exponent"}, &ignored, true);
    l.profile = profile;
  }
  node.CollectExtra({"id", "type", "position_mm", "direction", "intensity", "profile"}, &l.extra, false);
  return l;
}

// A frame path must stay inside the capture folder: relative, no "..", no empty or "." parts,
// '/' separators (the manifest is written on one system and read on another).
void CheckRelativePath(const Node& node, const std::string& file) {
  if (file.empty()) node.Fail("a relative path to the frame file (non-empty)");
  if (file.find('\\') != std::string::npos) node.Fail("a relative path with '/' separators, got \"" + file + "\"");
  if (file.front() == '/' || (file.size() > 1 && file[1] == ':')) {
    node.Fail("a path relative to the capture folder, got the absolute path \"" + file + "\"");
  }
  std::stringstream parts(file);
  std::string part;
  while (std::getline(parts, part, '/')) {
    if (part == "..") node.Fail("a path inside the capture folder (no \"..\"), got \"" + file + "\"");
    if (part.empty() || part == ".") node.Fail("a normalised relative path (no empty or \".\" parts), got \"" + file + "\"");
  }
  if (file.back() == '/') node.Fail("a path to a file, not a folder, got \"" + file + "\"");
}

FrameSpec ParseFrame(const Node& node, const Manifest& m) {
  node.ExpectObject("a frame {file, camera, light, side, exposure_s, role}");
  FrameSpec f;
  const Node file = node.Required("file", "the frame's path relative to the capture folder");
  f.file = file.String("a relative path to the frame file");
  CheckRelativePath(file, f.file);
  const Node cam = node.Required("camera", "the id of a camera in /cameras");
  f.camera = cam.String("a camera id");
  if (!m.FindCamera(f.camera)) cam.Fail("the id of a camera in /cameras, got unknown camera \"" + f.camera + "\"");
  if (node.Has("light") && !node.Child("light").value().is_null()) {
    const Node light = node.Child("light");
    f.light = light.String("a light id, or null for all lights off");
    if (!m.FindLight(*f.light)) light.Fail("the id of a light in /lights or null, got unknown light \"" + *f.light + "\"");
  }
  if (node.Has("side")) {
    const Node side = node.Child("side");
    f.side = side.String("\"front\" or \"back\"");
    if (f.side != "front" && f.side != "back") side.Fail("\"front\" or \"back\", got \"" + f.side + "\"");
  }
  f.exposure_s = node.Required("exposure_s", "the exposure time in seconds").Positive("an exposure time in seconds");
  const Node role = node.Required("role", "the frame role");
  const std::string role_name = role.String("a frame role");
  const auto parsed_role = FrameRoleFromName(role_name);
  if (!parsed_role) {
    role.Fail("one of the roles sample, ambient, dark, flat, board, sphere, chart, backlight; got \"" + role_name + "\"");
  }
  f.role = *parsed_role;
  node.CollectExtra({"file", "camera", "light", "side", "exposure_s", "role"}, &f.extra, false);
  return f;
}

// Roles and lights: a frame that measures one light must name it; "lights off" frames must not.
void CheckRoleLight(const Node& node, const FrameSpec& f) {
  switch (f.role) {
    case FrameRole::kSample:
    case FrameRole::kFlat:
    case FrameRole::kSphere:
      if (!f.light) {
        const std::string pointer = node.pointer() + "/light";
        throw InputError(node.file(), pointer,
                         std::string("the id of the light that lights this ") + FrameRoleName(f.role) +
                             " frame (null is only for frames with all lights off)");
      }
      break;
    case FrameRole::kDark:
    case FrameRole::kAmbient:
      if (f.light) {
        throw InputError(node.file(), node.pointer() + "/light",
                         std::string("null for a ") + FrameRoleName(f.role) + " frame (all lights off), got \"" +
                             *f.light + "\"");
      }
      break;
    default:
      break;
  }
}

// OpenCV's predefined ArUco dictionaries (cv::aruco::PREDEFINED_DICTIONARY_NAME).
const std::set<std::string>& ArucoDictionaries() {
  static const std::set<std::string> names = [] {
    std::set<std::string> n;
    for (int bits : {4, 5, 6, 7}) {
      for (int count : {50, 100, 250, 1000}) {
        n.insert("DICT_" + std::to_string(bits) + "X" + std::to_string(bits) + "_" + std::to_string(count));
      }
    }
    for (const char* s : {"DICT_ARUCO_ORIGINAL", "DICT_APRILTAG_16h5", "DICT_APRILTAG_25h9", "DICT_APRILTAG_36h10",
                          "DICT_APRILTAG_36h11"}) {
      n.insert(s);
    }
    return n;
  }();
  return names;
}

Targets ParseTargets(const Node& node) {
  node.ExpectObject("calibration targets {board, white, sphere, chart}");
  Targets t;
  json ignored;
  if (node.Has("board")) {
    const Node b = node.Child("board");
    b.ExpectObject("a ChArUco board {squares_x, squares_y, square_mm, marker_mm, dictionary}");
    BoardTarget board;
    board.squares_x = b.Required("squares_x", "squares along x").Integer("a number of squares", 2, 1000);
    board.squares_y = b.Required("squares_y", "squares along y").Integer("a number of squares", 2, 1000);
    board.square_mm = b.Required("square_mm", "the square side in mm").Positive("a square side in mm");
    const Node marker = b.Required("marker_mm", "the marker side in mm");
    board.marker_mm = marker.Positive("a marker side in mm");
    if (!(board.marker_mm < board.square_mm)) marker.Fail("a marker side smaller than square_mm");
    const Node dict = b.Required("dictionary", "an OpenCV ArUco dictionary name");
    board.dictionary = dict.String("an OpenCV ArUco dictionary name");
    if (!ArucoDictionaries().count(board.dictionary)) {
      dict.Fail("an OpenCV ArUco dictionary name such as DICT_5X5_100, got \"" + board.dictionary + "\"");
    }
    b.CollectExtra({"squares_x", "squares_y", "square_mm", "marker_mm", "dictionary"}, &ignored, true);
    t.board = board;
  }
  if (node.Has("white")) {
    const Node w = node.Child("white");
    w.ExpectObject("a white target {reflectance}");
    const Node r = w.Required("reflectance", "the white target's reflectance in (0, 1]");
    WhiteTarget white;
    white.reflectance = r.Positive("a reflectance in (0, 1]");
    if (white.reflectance > 1.0) r.Fail("a reflectance in (0, 1], got " + r.value().dump());
    w.CollectExtra({"reflectance"}, &ignored, true);
    t.white = white;
  }
  if (node.Has("sphere")) {
    const Node s = node.Child("sphere");
    s.ExpectObject("a mirror sphere {radius_mm, center_mm?}");
    SphereTarget sphere;
    sphere.radius_mm = s.Required("radius_mm", "the sphere radius in mm").Positive("a sphere radius in mm");
    if (s.Has("center_mm")) sphere.center_mm = s.Child("center_mm").Vector3("a sphere centre [x, y, z] in mm");
    s.CollectExtra({"radius_mm", "center_mm"}, &ignored, true);
    t.sphere = sphere;
  }
  if (node.Has("chart")) {
    const Node c = node.Child("chart");
    c.ExpectObject("a colour chart {type}");
    ChartTarget chart;
    chart.type = c.Required("type", "the chart type, e.g. \"macbeth24\"").NonEmptyString("a chart type");
    c.CollectExtra({"type"}, &ignored, true);
    t.chart = chart;
  }
  node.CollectExtra({"board", "white", "sphere", "chart"}, &t.extra, false);
  return t;
}

// A role that needs a target description: the pointer names the frame's role.
void CheckRoleTarget(const Node& frame_node, const FrameSpec& f, const Targets& t) {
  const char* needed = nullptr;
  bool present = true;
  switch (f.role) {
    case FrameRole::kBoard: needed = "board"; present = t.board.has_value(); break;
    case FrameRole::kFlat: needed = "white"; present = t.white.has_value(); break;
    case FrameRole::kSphere: needed = "sphere"; present = t.sphere.has_value(); break;
    case FrameRole::kChart: needed = "chart"; present = t.chart.has_value(); break;
    default: break;
  }
  if (!present) {
    throw InputError(frame_node.file(), frame_node.pointer() + "/role",
                     std::string("a /targets/") + needed + " description for a " + FrameRoleName(f.role) +
                         " frame; /targets/" + needed + " is missing");
  }
}

json Vec3(const Eigen::Vector3d& v) { return json::array({v.x(), v.y(), v.z()}); }

void MergeExtra(json* object, const json& extra) {
  if (!extra.is_object()) return;
  for (auto it = extra.begin(); it != extra.end(); ++it) {
    if (!object->contains(it.key())) (*object)[it.key()] = it.value();
  }
}

std::string ReadText(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path.string(), "", "a readable capture manifest (capture.json)");
  std::ostringstream s;
  s << in.rdbuf();
  if (in.bad()) throw InputError(path.string(), "", "a readable capture manifest (capture.json)");
  return s.str();
}

}  // namespace

const char* FrameRoleName(FrameRole role) {
  switch (role) {
    case FrameRole::kSample: return "sample";
    case FrameRole::kAmbient: return "ambient";
    case FrameRole::kDark: return "dark";
    case FrameRole::kFlat: return "flat";
    case FrameRole::kBoard: return "board";
    case FrameRole::kSphere: return "sphere";
    case FrameRole::kChart: return "chart";
    case FrameRole::kBacklight: return "backlight";
  }
  return "unknown";
}

std::optional<FrameRole> FrameRoleFromName(const std::string& name) {
  for (FrameRole role : {FrameRole::kSample, FrameRole::kAmbient, FrameRole::kDark, FrameRole::kFlat,
                         FrameRole::kBoard, FrameRole::kSphere, FrameRole::kChart, FrameRole::kBacklight}) {
    if (name == FrameRoleName(role)) return role;
  }
  return std::nullopt;
}

const CameraSpec* Manifest::FindCamera(const std::string& id) const {
  for (const auto& camera : cameras) {
    if (camera.id == id) return &camera;
  }
  return nullptr;
}

const LightSpec* Manifest::FindLight(const std::string& id) const {
  for (const auto& light : lights) {
    if (light.id == id) return &light;
  }
  return nullptr;
}

namespace {

// A manifest is a few kilobytes and a few levels deep; deeper nesting is hostile (recursive copies
// of such a tree overflow the stack).
constexpr int kMaxManifestDepth = 64;

// Parses JSON refusing duplicate keys (which the JSON grammar allows but makes ambiguous: one
// reader takes the first, another the last) and nesting deeper than kMaxManifestDepth. Errors name
// the JSON pointer of the offending key.
json ParseStrictJson(const std::string& text, const std::string& source_name) {
  struct Level {
    bool is_array = false;
    long index = -1;          // array: index of the current element
    std::string key;          // object: the current key
    std::set<std::string> keys;
  };
  std::vector<Level> levels;
  auto pointer = [&levels]() {
    std::string p;
    for (const Level& level : levels) {
      if (level.is_array) {
        if (level.index >= 0) p += "/" + std::to_string(level.index);
      } else if (!level.key.empty()) {
        p += "/" + level.key;
      }
    }
    return p;
  };
  auto element_starts = [&levels]() {
    if (!levels.empty() && levels.back().is_array) ++levels.back().index;
  };
  json::parser_callback_t callback = [&](int depth, json::parse_event_t event, json& parsed) {
    if (depth > kMaxManifestDepth) {
      throw InputError(source_name, pointer(), "JSON nested at most " + std::to_string(kMaxManifestDepth) + " levels deep");
    }
    switch (event) {
      case json::parse_event_t::object_start:
      case json::parse_event_t::array_start:
        element_starts();
        levels.push_back(Level{event == json::parse_event_t::array_start, -1, {}, {}});
        break;
      case json::parse_event_t::object_end:
      case json::parse_event_t::array_end:
        if (!levels.empty()) levels.pop_back();
        break;
      case json::parse_event_t::key: {
        Level& level = levels.back();
        level.key = parsed.get<std::string>();
        if (!level.keys.insert(level.key).second) {
          throw InputError(source_name, pointer(), "each key once per object; \"" + level.key + "\" appears twice");
        }
        break;
      }
      case json::parse_event_t::value:
        element_starts();
        break;
    }
    return true;
  };
  try {
    return json::parse(text, callback);
  } catch (const json::exception& e) {  // syntax errors, and numbers beyond double (1e999)
    throw InputError(source_name, pointer(), std::string("valid JSON with finite numbers: ") + e.what());
  }
}

}  // namespace

Manifest ParseManifest(const std::string& json_text, const std::string& source_name) {
  const json doc = ParseStrictJson(json_text, source_name);
  const Node root(doc, source_name, "");
  root.ExpectObject("a capture manifest");

  Manifest m;
  const Node format = root.Required("format", std::string("\"") + kCaptureFormat + "\"");
  m.format = format.String(std::string("the format \"") + kCaptureFormat + "\"");
  if (m.format != kCaptureFormat) format.Fail(std::string("\"") + kCaptureFormat + "\", got \"" + m.format + "\"");

  if (root.Has("scanner")) m.scanner = ParseScanner(root.Child("scanner"));
  if (root.Has("sample")) m.sample = ParseSample(root.Child("sample"));
  if (root.Has("output")) m.output = ParseOutput(root.Child("output"));

  const Node cameras = root.Required("cameras", "an array of cameras");
  cameras.ExpectArray("the cameras");
  if (cameras.value().empty()) cameras.Fail("at least one camera");
  for (std::size_t i = 0; i < cameras.value().size(); ++i) {
    const Node node = cameras.Child(i);
    CameraSpec camera = ParseCamera(node);
    if (m.FindCamera(camera.id)) node.Child("id").Fail("a camera id used once, \"" + camera.id + "\" is used before");
    m.cameras.push_back(std::move(camera));
  }

  const Node lights = root.Required("lights", "an array of lights");
  lights.ExpectArray("the lights");
  for (std::size_t i = 0; i < lights.value().size(); ++i) {
    const Node node = lights.Child(i);
    LightSpec light = ParseLight(node);
    if (m.FindLight(light.id)) node.Child("id").Fail("a light id used once, \"" + light.id + "\" is used before");
    m.lights.push_back(std::move(light));
  }

  if (root.Has("targets")) m.targets = ParseTargets(root.Child("targets"));

  const Node frames = root.Required("frames", "an array of frames");
  frames.ExpectArray("the frames");
  std::map<std::string, std::size_t> files;
  bool has_sample = false;
  for (std::size_t i = 0; i < frames.value().size(); ++i) {
    const Node node = frames.Child(i);
    FrameSpec frame = ParseFrame(node, m);
    CheckRoleLight(node, frame);
    CheckRoleTarget(node, frame, m.targets);
    if (auto [it, inserted] = files.emplace(frame.file, i); !inserted) {
      node.Child("file").Fail("a file used by one frame only, \"" + frame.file + "\" is also /frames/" +
                              std::to_string(it->second) + "/file");
    }
    has_sample = has_sample || frame.role == FrameRole::kSample;
    m.frames.push_back(std::move(frame));
  }
  if (!has_sample) frames.Fail("at least one frame with role \"sample\"");

  root.CollectExtra({"format", "scanner", "sample", "output", "cameras", "lights", "frames", "targets"}, &m.extra,
                    false);
  return m;
}

json ManifestToJson(const Manifest& m) {
  json j = json::object();
  j["format"] = m.format;
  json scanner = {{"vendor", m.scanner.vendor}, {"model", m.scanner.model}, {"serial", m.scanner.serial},
                  {"software", m.scanner.software}};
  MergeExtra(&scanner, m.scanner.extra);
  j["scanner"] = scanner;
  json sample = {{"name", m.sample.name}, {"description", m.sample.description}};
  if (m.sample.thickness_mm) sample["thickness_mm"] = *m.sample.thickness_mm;
  if (m.sample.weight_gsm) sample["weight_gsm"] = *m.sample.weight_gsm;
  MergeExtra(&sample, m.sample.extra);
  j["sample"] = sample;
  if (m.output.dpi || m.output.region_mm) {
    json output = json::object();
    if (m.output.dpi) output["dpi"] = *m.output.dpi;
    if (m.output.region_mm) output["region_mm"] = *m.output.region_mm;
    j["output"] = output;
  }

  json cameras = json::array();
  for (const auto& c : m.cameras) {
    json cj = {{"id", c.id},
               {"width", c.width},
               {"height", c.height},
               {"intrinsics", {{"fx", c.intrinsics.fx}, {"fy", c.intrinsics.fy}, {"cx", c.intrinsics.cx}, {"cy", c.intrinsics.cy}}},
               {"distortion", c.distortion}};
    if (c.pose) {
      json rotation = json::array();
      for (int i = 0; i < 3; ++i) {
        rotation.push_back({c.pose->rotation(i, 0), c.pose->rotation(i, 1), c.pose->rotation(i, 2)});
      }
      cj["pose"] = {{"rotation", rotation}, {"translation_mm", Vec3(c.pose->translation_mm)}};
    }
    if (c.response) cj["response"] = {{"black_level", c.response->black_level}, {"white_level", c.response->white_level}};
    if (c.white_balance) cj["white_balance"] = *c.white_balance;
    MergeExtra(&cj, c.extra);
    cameras.push_back(cj);
  }
  j["cameras"] = cameras;

  json lights = json::array();
  for (const auto& l : m.lights) {
    json lj = {{"id", l.id}, {"type", l.type == ManifestLightType::kPoint ? "point" : "directional"}};
    if (l.position_mm) lj["position_mm"] = Vec3(*l.position_mm);
    if (l.direction) lj["direction"] = Vec3(*l.direction);
    lj["intensity"] = Vec3(l.intensity_rgb);
    if (l.profile) lj["profile"] = {{"axis", Vec3(l.profile->axis)}, {"exponent", l.profile->exponent}};
    MergeExtra(&lj, l.extra);
    lights.push_back(lj);
  }
  j["lights"] = lights;

  json frames = json::array();
  for (const auto& f : m.frames) {
    json fj = {{"file", f.file}, {"camera", f.camera}};
    fj["light"] = f.light ? json(*f.light) : json(nullptr);
    fj["side"] = f.side;
    fj["exposure_s"] = f.exposure_s;
    fj["role"] = FrameRoleName(f.role);
    MergeExtra(&fj, f.extra);
    frames.push_back(fj);
  }
  j["frames"] = frames;

  json targets = json::object();
  if (m.targets.board) {
    const auto& b = *m.targets.board;
    targets["board"] = {{"squares_x", b.squares_x}, {"squares_y", b.squares_y}, {"square_mm", b.square_mm},
                        {"marker_mm", b.marker_mm}, {"dictionary", b.dictionary}};
  }
  if (m.targets.white) targets["white"] = {{"reflectance", m.targets.white->reflectance}};
  if (m.targets.sphere) {
    json s = {{"radius_mm", m.targets.sphere->radius_mm}};
    if (m.targets.sphere->center_mm) s["center_mm"] = Vec3(*m.targets.sphere->center_mm);
    targets["sphere"] = s;
  }
  if (m.targets.chart) targets["chart"] = {{"type", m.targets.chart->type}};
  MergeExtra(&targets, m.targets.extra);
  if (!targets.empty()) j["targets"] = targets;

  MergeExtra(&j, m.extra);
  return j;
}

Manifest ReadManifest(const fs::path& capture_dir_or_file, std::vector<FrameHeader>* headers) {
  std::error_code ec;
  const bool is_dir = fs::is_directory(capture_dir_or_file, ec);
  const fs::path file = is_dir ? capture_dir_or_file / kManifestFileName : capture_dir_or_file;
  const fs::path folder = is_dir ? capture_dir_or_file : capture_dir_or_file.parent_path();
  const std::string name = file.string();
  if (!fs::is_regular_file(file, ec)) {
    throw InputError(name, "", "a capture manifest file (capture.json in the capture folder); it does not exist");
  }
  Manifest m = ParseManifest(ReadText(file), name);

  const fs::path canonical_folder = fs::weakly_canonical(fs::absolute(folder), ec);
  if (headers != nullptr) headers->clear();
  for (std::size_t i = 0; i < m.frames.size(); ++i) {
    const FrameSpec& f = m.frames[i];
    const std::string pointer = "/frames/" + std::to_string(i) + "/file";
    const fs::path path = folder / f.file;
    if (!fs::is_regular_file(path, ec)) {
      throw InputError(name, pointer, "an existing frame file, \"" + f.file + "\" is not a file in " + folder.string());
    }
    // A symlink may still lead out of the folder; the contract keeps every frame inside it.
    const fs::path canonical = fs::weakly_canonical(fs::absolute(path), ec);
    const auto rel = canonical.lexically_relative(canonical_folder);
    if (rel.empty() || *rel.begin() == "..") {
      throw InputError(name, pointer, "a frame file inside the capture folder, \"" + f.file + "\" leads to " + canonical.string());
    }
    FrameHeader header;
    try {
      header = ReadFrameHeader(path);
    } catch (const InputError& e) {
      throw InputError(name, pointer, "a readable image file: " + std::string(e.what()));
    }
    const CameraSpec* camera = m.FindCamera(f.camera);
    if (header.width != camera->width || header.height != camera->height) {
      throw InputError(name, pointer,
                       "an image of camera \"" + camera->id + "\"'s size " + std::to_string(camera->width) + "x" +
                           std::to_string(camera->height) + ", \"" + f.file + "\" is " + std::to_string(header.width) +
                           "x" + std::to_string(header.height));
    }
    if (headers != nullptr) headers->push_back(header);
  }
  return m;
}

void WriteManifest(const Manifest& manifest, const fs::path& capture_dir) {
  const fs::path file = capture_dir / kManifestFileName;
  const std::string text = ManifestToJson(manifest).dump(2) + "\n";
  // Refuse to write what a reader would refuse; the message names the file it would have become.
  ParseManifest(text, file.string());

  std::error_code ec;
  fs::create_directories(capture_dir, ec);
  if (ec) throw InputError(capture_dir.string(), "", "a folder that can be created: " + ec.message());
  const fs::path temp = capture_dir / ".capture.json.partial";
  {
    std::ofstream out(temp, std::ios::binary | std::ios::trunc);
    out << text;
    out.flush();
    if (!out) {
      fs::remove(temp, ec);
      throw InputError(file.string(), "", "a writable location for the manifest");
    }
  }
  fs::rename(temp, file, ec);
  if (ec) {
    std::error_code ignored;
    fs::remove(temp, ignored);
    throw InputError(file.string(), "", "a location the manifest can be renamed into: " + ec.message());
  }
}

}  // namespace u3mscan
