#include "datasets_synthetic/capture_writer.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <vector>

#include "capture/dng_writer.h"
#include "capture/manifest.h"
#include "core/elapsed.h"
#include "core/error.h"
#include "core/logging.h"
#include "core/units.h"
#include "datasets_synthetic/atomic_folder.h"
#include "datasets_synthetic/calibration_frames.h"
#include "datasets_synthetic/renderer.h"
#include "datasets_synthetic/sensor.h"
#include "datasets_synthetic/truth_writer.h"
#include "u3m/image_io.h"

namespace u3mscan::synthetic {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// 2020-01-01 00:00:00 UTC, the DateTime of every synthetic TIFF frame.
constexpr std::time_t kFrameTimestampUtc = 1577836800;

const char* FrameExtension(FrameFormat format) {
  switch (format) {
    case FrameFormat::kDng: return ".dng";
    case FrameFormat::kTiff: return ".tif";
    case FrameFormat::kExr: return ".exr";
  }
  return ".dng";
}

// One frame to render: what it is in the manifest and how to make its linear image.
struct FrameJob {
  FrameSpec spec;
  int camera = 0;
  std::function<Image(SceneRenderer&)> render;
};

// The light closest to the zenith lights the board and chart frames most evenly.
int HighestLight(const Rig& rig) {
  int best = 0;
  double best_z = -2;
  for (std::size_t i = 0; i < rig.lights.size(); ++i) {
    const RigLight& l = rig.lights[i];
    const double z = l.type == RigLightType::kDirectional ? l.direction.z() : l.position_mm.normalized().z();
    if (z > best_z) {
      best_z = z;
      best = static_cast<int>(i);
    }
  }
  return best;
}

bool HasHoles(const SceneTruth& scene) {
  for (float a : scene.alpha.plane(0)) {
    if (a < 1.0f) return true;
  }
  return false;
}

std::vector<FrameJob> PlanFrames(const SceneTruth& scene, const Rig& rig, const CaptureOptions& options,
                                 const CalibrationTargets& targets) {
  std::vector<FrameJob> jobs;
  const std::string ext = FrameExtension(options.format);
  auto add = [&](int camera, const std::string& file, FrameRole role, std::optional<int> light,
                 std::function<Image(SceneRenderer&)> render) {
    FrameJob job;
    job.camera = camera;
    job.spec.file = file;
    job.spec.camera = rig.cameras[camera].id;
    if (light) job.spec.light = rig.lights[*light].id;
    job.spec.exposure_s = rig.exposure_s;
    job.spec.role = role;
    job.render = std::move(render);
    jobs.push_back(std::move(job));
  };
  const int board_light = HighestLight(rig);
  auto wanted = [&options](FrameRole role) { return options.calibration_roles.count(role) > 0; };
  const bool ambient = rig.ambient_irradiance > 0;
  for (int c = 0; c < static_cast<int>(rig.cameras.size()); ++c) {
    const std::string cam = rig.cameras[c].id;
    for (int l = 0; l < static_cast<int>(rig.lights.size()); ++l) {
      add(c, "frames/" + cam + "/" + rig.lights[l].id + ext, FrameRole::kSample, l, [l, ambient](SceneRenderer& r) {
        Image img = r.RenderLight(l);
        if (ambient) {
          const Image& amb = r.AmbientImage();
          for (std::size_t i = 0; i < img.data().size(); ++i) img.data()[i] += amb.data()[i];
        }
        return img;
      });
    }
    if (ambient) add(c, "frames/" + cam + "/ambient" + ext, FrameRole::kAmbient, std::nullopt, [](SceneRenderer& r) { return r.AmbientImage(); });
    if (!options.calibration_frames) continue;
    const std::string dir = "calibration/" + cam + "/";
    if (wanted(FrameRole::kDark)) {
      add(c, dir + "dark" + ext, FrameRole::kDark, std::nullopt, [&rig, c](SceneRenderer&) { return RenderDarkFrame(rig, c); });
    }
    for (int l = 0; wanted(FrameRole::kFlat) && l < static_cast<int>(rig.lights.size()); ++l) {
      add(c, dir + "flat_" + rig.lights[l].id + ext, FrameRole::kFlat, l,
          [&rig, &targets, c, l](SceneRenderer&) { return RenderFlatFrame(rig, c, targets, l); });
    }
    if (wanted(FrameRole::kBoard)) {
      add(c, dir + "board" + ext, FrameRole::kBoard, board_light,
          [&rig, &targets, c, board_light](SceneRenderer&) { return RenderBoardFrame(rig, c, targets, board_light); });
    }
    if (wanted(FrameRole::kBacklight) && HasHoles(scene)) {
      const double level = targets.backlight_level;
      add(c, dir + "backlight" + ext, FrameRole::kBacklight, std::nullopt, [level](SceneRenderer& r) {
        const Image a = r.RenderBacklight(level);
        Image rgb(a.width(), a.height(), 3);
        for (int ch = 0; ch < 3; ++ch) std::copy(a.plane(0).begin(), a.plane(0).end(), rgb.plane(ch).begin());
        return rgb;
      });
    }
    if (c != 0) continue;  // lights and colour are calibrated from the top camera
    for (std::size_t p = 0; wanted(FrameRole::kSphere) && p < targets.sphere_centers_mm.size(); ++p) {
      for (int l = 0; l < static_cast<int>(rig.lights.size()); ++l) {
        add(c, dir + "sphere_p" + std::to_string(p) + "_" + rig.lights[l].id + ext, FrameRole::kSphere, l,
            [&rig, &targets, c, l, p](SceneRenderer&) { return RenderSphereFrame(rig, c, targets, l, static_cast<int>(p)); });
        jobs.back().spec.extra["sphere_placement"] = p;
      }
    }
    if (wanted(FrameRole::kChart)) {
      add(c, dir + "chart" + ext, FrameRole::kChart, board_light,
          [&rig, &targets, c, board_light](SceneRenderer&) { return RenderChartFrame(rig, c, targets, board_light); });
    }
  }
  return jobs;
}

Manifest BuildManifest(const SceneTruth& scene, const Rig& rig, const CaptureOptions& options,
                       const CalibrationTargets& targets, const std::vector<FrameJob>& jobs) {
  Manifest m;
  m.scanner = {"u3mscan", "synthetic " + rig.name, "seed " + std::to_string(rig.seed), options.scanner_software, json::object()};
  m.sample.name = scene.name;
  m.sample.description = "synthetic scene '" + scene.name + "' rendered with rig '" + rig.name + "'";
  if (options.write_thickness) {
    float top = 0.0f;
    for (float h : scene.height_mm.plane(0)) top = std::max(top, h);
    if (top > 0.0f) m.sample.thickness_mm = static_cast<double>(top);
  }
  // The maps cover exactly the sample's truth grid, so finished maps and truth maps align pixel for pixel.
  const double half_w = 0.5 * scene.height_mm.width() * scene.pitch_mm, half_h = 0.5 * scene.height_mm.height() * scene.pitch_mm;
  m.output.dpi = PitchMmToDpi(scene.pitch_mm);
  m.output.region_mm = std::array<double, 4>{-half_w, -half_h, half_w, half_h};
  for (const RigCamera& rc : rig.cameras) {
    CameraSpec c;
    c.id = rc.id;
    c.width = rc.width;
    c.height = rc.height;
    c.intrinsics = {rc.fx, rc.fy, rc.cx, rc.cy};
    c.distortion = rc.distortion;
    if (options.write_pose) c.pose = CameraPose{rc.world_from_camera, rc.position_mm};
    switch (options.format) {
      case FrameFormat::kDng:
        c.white_balance = std::array<double, 3>{1.0, 1.0, 1.0};  // raw sensor colour = linear sRGB here
        break;
      case FrameFormat::kTiff:
        c.response = SensorResponse{0.0, 65535.0};
        break;
      case FrameFormat::kExr:
        c.response = SensorResponse{0.0, 1.0};
        break;
    }
    m.cameras.push_back(std::move(c));
  }
  for (const RigLight& rl : rig.lights) {
    LightSpec l;
    l.id = rl.id;
    l.intensity_rgb = rl.intensity_rgb;
    if (rl.type == RigLightType::kPoint) {
      l.type = ManifestLightType::kPoint;
      l.position_mm = rl.position_mm;
      if (rl.profile_exponent > 0) l.profile = LightProfile{rl.profile_axis, rl.profile_exponent};
    } else {
      l.type = ManifestLightType::kDirectional;
      l.direction = rl.direction;
    }
    m.lights.push_back(std::move(l));
  }
  for (const FrameJob& job : jobs) m.frames.push_back(job.spec);
  // The targets of the frames written, and only those (a manifest describes what it uses).
  auto written = [&jobs](FrameRole role) {
    return std::any_of(jobs.begin(), jobs.end(), [role](const FrameJob& job) { return job.spec.role == role; });
  };
  if (written(FrameRole::kBoard)) {
    const BoardSpec& b = targets.board;
    m.targets.board = BoardTarget{b.squares_x, b.squares_y, b.square_mm, b.marker_mm, b.dictionary};
  }
  if (written(FrameRole::kFlat)) m.targets.white = WhiteTarget{targets.white_reflectance};
  if (written(FrameRole::kSphere)) {
    SphereTarget sphere;
    sphere.radius_mm = targets.sphere_radius_mm;
    if (targets.sphere_centers_mm.size() == 1) sphere.center_mm = targets.sphere_centers_mm[0];
    m.targets.sphere = sphere;
  }
  if (written(FrameRole::kChart)) m.targets.chart = ChartTarget{"macbeth24"};
  return m;
}

json Vec(const Eigen::Vector3d& v) { return json::array({v.x(), v.y(), v.z()}); }

json RigTruth(const SceneTruth& scene, const Rig& rig, const CaptureOptions& options, const CalibrationTargets& t) {
  json cams = json::array();
  for (const RigCamera& c : rig.cameras) {
    json r = json::array();
    for (int i = 0; i < 3; ++i) r.push_back({c.world_from_camera(i, 0), c.world_from_camera(i, 1), c.world_from_camera(i, 2)});
    const char* vig = c.vignetting == VignettingModel::kNone ? "none" : c.vignetting == VignettingModel::kCos4 ? "cos4" : "polynomial";
    cams.push_back({{"id", c.id}, {"width", c.width}, {"height", c.height},
                    {"intrinsics", {{"fx", c.fx}, {"fy", c.fy}, {"cx", c.cx}, {"cy", c.cy}}},
                    {"distortion", c.distortion},
                    {"world_from_camera", {{"rotation", r}, {"translation_mm", Vec(c.position_mm)}}},
                    {"vignetting", {{"model", vig}, {"coefficients", c.vignetting_poly}}}});
  }
  json lights = json::array();
  for (const RigLight& l : rig.lights) {
    json j = {{"id", l.id}, {"intensity", Vec(l.intensity_rgb)}};
    if (l.type == RigLightType::kPoint) {
      j["type"] = "point";
      j["position_mm"] = Vec(l.position_mm);
      j["profile"] = {{"axis", Vec(l.profile_axis)}, {"exponent", l.profile_exponent}};
      j["emitter_radius_mm"] = l.emitter_radius;
    } else {
      j["type"] = "directional";
      j["direction"] = Vec(l.direction);
      j["emitter_radius_deg"] = l.emitter_radius;
    }
    lights.push_back(j);
  }
  const SensorSpec& s = rig.sensor;
  json patches = json::array();
  for (int k = 0; k < 24; ++k) patches.push_back(Vec(ColorCheckerLinear(k)));
  json sphere_centers = json::array();
  for (const auto& c : t.sphere_centers_mm) sphere_centers.push_back(Vec(c));
  const double half_w = 0.5 * scene.height_mm.width() * scene.pitch_mm, half_h = 0.5 * scene.height_mm.height() * scene.pitch_mm;
  return {
      {"name", rig.name},
      {"seed", rig.seed},
      {"frame_format", FrameFormatName(options.format)},
      {"sample_rect_mm", {-half_w, -half_h, half_w, half_h}},
      // The scene's own grid frame (truth "grid": x = col p, y = -row p) sits shifted in the
      // capture's world so that the sample is centred on the origin: world = scene + this.
      {"world_from_scene_translation_mm", {-half_w + 0.5 * scene.pitch_mm, half_h - 0.5 * scene.pitch_mm, 0.0}},
      {"sample_pitch_mm", scene.pitch_mm},
      {"cameras", cams},
      {"lights", lights},
      {"sensor",
       {{"bit_depth", s.bit_depth}, {"black_level_dn", s.black_level_dn}, {"white_level_dn", s.white_level_dn},
        {"full_well_e", s.full_well_e}, {"read_noise_e", s.read_noise_e}, {"fixed_pattern_dn", s.fixed_pattern_dn},
        {"noise", s.noise}, {"cfa", "RGGB"}}},
      {"exposure_s", rig.exposure_s},
      {"ambient_irradiance", rig.ambient_irradiance},
      {"table_reflectance", rig.table_reflectance},
      {"ground_pitch_mm", rig.ground_pitch_mm},
      {"targets",
       {{"board",
         {{"squares_x", t.board.squares_x}, {"squares_y", t.board.squares_y}, {"square_mm", t.board.square_mm},
          {"marker_mm", t.board.marker_mm}, {"dictionary", t.board.dictionary},
          {"world_from_board", {{"rotation", {{1, 0, 0}, {0, -1, 0}, {0, 0, -1}}},
                                {"translation_mm", {t.board.origin_mm[0], t.board.origin_mm[1], 0.0}}}}}},
        {"white_reflectance", t.white_reflectance},
        {"sphere", {{"radius_mm", t.sphere_radius_mm}, {"centers_mm", sphere_centers}, {"highlight_level", t.sphere_highlight_level}}},
        {"chart", {{"type", "macbeth24"}, {"rect_mm", t.chart_rect_mm}, {"patch_mm", t.chart_patch_mm}, {"patches_linear_srgb", patches}}},
        {"backlight_level", t.backlight_level}}},
      {"units",
       {{"length", "mm"}, {"angle", "deg"}, {"time", "s"},
        {"intensity", "contract units: decoded value = exposure_s * f * cos * intensity * profile / d_mm^2 (point) or * intensity (directional)"},
        {"frame", "world: sample plane z = 0, +z toward the camera, +x right, +y up; poses world_from_camera, OpenCV camera axes"}}},
  };
}

void WriteFrame(const RawFrame& raw, const SensorSpec& sensor, FrameFormat format, const fs::path& path) {
  fs::create_directories(path.parent_path());
  if (format == FrameFormat::kDng) {
    DngWriteOptions dng;
    dng.pattern = CfaPattern::kRggb;
    dng.black_level = static_cast<std::uint16_t>(sensor.black_level_dn);
    dng.white_level = static_cast<std::uint16_t>(sensor.white_level_dn);
    WriteDng(path, raw.dn, raw.width, raw.height, dng);
    return;
  }
  ImageWriteOptions w;
  w.encoding = PixelEncoding::kLinear;
  w.format = format == FrameFormat::kTiff ? SampleFormat::kUInt16 : SampleFormat::kFloat32;
  w.modified_utc = kFrameTimestampUtc;  // a fixed TIFF DateTime: the same seed writes the same bytes
  WriteImageFile(RawToLinear(raw, sensor), path, w);
}

// Hand-made scenes (tests) may leave maps empty; the renderer reads those as its defaults, and the
// truth must hold what was rendered, so they are filled with the same defaults before writing.
bool HasEveryMap(const SceneTruth& s) {
  for (const Image* m : {&s.height_mm, &s.normal, &s.base_color, &s.roughness, &s.specular, &s.specular_tint, &s.sheen,
                         &s.sheen_tint, &s.metallic, &s.anisotropic, &s.alpha, &s.tangent}) {
    if (m->empty()) return false;
  }
  return true;
}

SceneTruth CompletedScene(const SceneTruth& scene) {
  SceneTruth s = scene;
  const int w = s.height_mm.width(), h = s.height_mm.height();
  const double p = s.pitch_mm;
  auto fill = [&](Image& m, std::initializer_list<float> values) {
    if (!m.empty()) return;
    m = Image(w, h, static_cast<int>(values.size()), 0.0f, p);
    int c = 0;
    for (float v : values) std::fill(m.plane(c).begin(), m.plane(c).end(), v), ++c;
  };
  fill(s.normal, {0.0f, 0.0f, 1.0f});
  fill(s.base_color, {0.8f, 0.8f, 0.8f});
  fill(s.roughness, {0.5f});
  fill(s.specular, {0.5f});
  fill(s.specular_tint, {0.0f});
  fill(s.sheen, {0.0f});
  fill(s.sheen_tint, {0.0f});
  fill(s.metallic, {0.0f});
  fill(s.anisotropic, {0.0f});
  fill(s.alpha, {1.0f});
  fill(s.tangent, {1.0f, 0.0f, 0.0f});
  return s;
}

// A frame's noise stream is named by its path without the extension, so the DNG, TIFF and EXR
// captures of one seed carry the same noise.
std::string NoiseName(const std::string& file) { return fs::path(file).replace_extension().generic_string(); }

void WriteEverything(const SceneTruth& render_scene, const SceneTruth& scene, const Rig& rig, const CaptureOptions& options,
                     const fs::path& root, const TruthWriter& truth_writer, CaptureStats* stats) {
  const CalibrationTargets targets = MakeCalibrationTargets(rig);
  const std::vector<FrameJob> jobs = PlanFrames(render_scene, rig, options, targets);
  const fs::path capture_dir = root / kCaptureSubdir;
  fs::create_directories(capture_dir);
  RenderOptions render_options;
  render_options.supersample = options.supersample;
  SceneRenderer renderer(render_scene, rig, render_options);
  for (std::size_t k = 0; k < jobs.size(); ++k) {
    const FrameJob& job = jobs[k];
    const RigCamera& cam = rig.cameras[job.camera];
    const double start = SteadySeconds();
    if (renderer.camera_index() != job.camera) renderer.SetCamera(job.camera);
    const Image linear = job.render(renderer);
    const RawFrame raw = ExposeSensor(linear, rig.sensor, FrameSeed(rig.seed, "camera:" + cam.id),
                                      FrameSeed(rig.seed, NoiseName(job.spec.file)), options.format == FrameFormat::kDng);
    stats->render_seconds += SteadySeconds() - start;
    stats->megapixels_rendered += 1e-6 * cam.width * cam.height;
    WriteFrame(raw, rig.sensor, options.format, capture_dir / job.spec.file);
    ++stats->frames;
    ReportProgress(options.progress, "synth", static_cast<double>(k + 1) / jobs.size());
  }
  WriteManifest(BuildManifest(scene, rig, options, targets, jobs), capture_dir);

  const json extra = {{"rig", RigTruth(scene, rig, options, targets)}};
  const fs::path truth_dir = root / kTruthSubdir;
  if (truth_writer) {
    truth_writer(scene, extra, truth_dir);
  } else if (HasEveryMap(scene)) {
    WriteTruth(scene, extra, truth_dir);
  } else {
    WriteTruth(CompletedScene(scene), extra, truth_dir);
  }
}

}  // namespace

const char* FrameFormatName(FrameFormat format) {
  switch (format) {
    case FrameFormat::kDng: return "dng";
    case FrameFormat::kTiff: return "tiff";
    case FrameFormat::kExr: return "exr";
  }
  return "dng";
}

std::optional<FrameFormat> FrameFormatFromName(const std::string& name) {
  if (name == "dng") return FrameFormat::kDng;
  if (name == "tiff" || name == "tif") return FrameFormat::kTiff;
  if (name == "exr") return FrameFormat::kExr;
  return std::nullopt;
}

std::set<FrameRole> AllCalibrationRoles() {
  return {FrameRole::kDark, FrameRole::kFlat, FrameRole::kBoard, FrameRole::kSphere, FrameRole::kChart,
          FrameRole::kBacklight};
}

std::set<FrameRole> CalibrationRolesFromList(const std::string& list, const std::string& option) {
  if (list == "all") return AllCalibrationRoles();
  const std::set<FrameRole> all = AllCalibrationRoles();
  std::set<FrameRole> roles;
  std::size_t start = 0;
  while (start <= list.size()) {
    const std::size_t comma = std::min(list.find(',', start), list.size());
    const std::string name = list.substr(start, comma - start);
    const std::optional<FrameRole> role = FrameRoleFromName(name);
    if (!role || all.count(*role) == 0) {
      throw InputError(option, "",
                       "a comma-separated list of calibration roles (dark, flat, board, sphere, chart, backlight) "
                       "or 'all', got '" + name + "' in '" + list + "'");
    }
    roles.insert(*role);
    start = comma + 1;
  }
  return roles;
}

CaptureStats WriteSyntheticCapture(const SceneTruth& scene, const Rig& rig, const CaptureOptions& options,
                                   const fs::path& out_dir, const TruthWriter& truth_writer) {
  return WriteSyntheticCapture(scene, scene, rig, options, out_dir, truth_writer);
}

CaptureStats WriteSyntheticCapture(const SceneTruth& render_scene, const SceneTruth& scene, const Rig& rig,
                                   const CaptureOptions& options, const fs::path& out_dir,
                                   const TruthWriter& truth_writer) {
  const double start = SteadySeconds();
  if (!options.Check()) throw std::invalid_argument("WriteSyntheticCapture: supersample must be >= 1");
  // Same rectangle: the renderer centres render_scene on the origin, the manifest's grid is scene's.
  const double tolerance = 1e-9 * (1.0 + scene.height_mm.width() * scene.pitch_mm + scene.height_mm.height() * scene.pitch_mm);
  if (std::abs(render_scene.height_mm.width() * render_scene.pitch_mm - scene.height_mm.width() * scene.pitch_mm) > tolerance ||
      std::abs(render_scene.height_mm.height() * render_scene.pitch_mm - scene.height_mm.height() * scene.pitch_mm) > tolerance) {
    throw std::invalid_argument("WriteSyntheticCapture: the rendered scene and the truth cover different rectangles");
  }
  CaptureStats stats;
  WriteFolderAtomically(out_dir, [&](const fs::path& staging) {
    WriteEverything(render_scene, scene, rig, options, staging, truth_writer, &stats);
  });
  stats.total_seconds = SteadySeconds() - start;
  LogInfo() << "synth: " << stats.frames << " frames, " << stats.megapixels_rendered << " MP rendered at "
            << stats.MegapixelsPerSecond() << " MP/s (" << stats.total_seconds << " s in all) -> "
            << fs::absolute(out_dir).lexically_normal().string();
  return stats;
}

}  // namespace u3mscan::synthetic
