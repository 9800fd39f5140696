// Stability suite (issue 8, docs/stability.md): every extreme preset of the synthetic scanner and
// a set of degenerate inputs through the whole pipeline (`ProcessCapture`). For each case: no NaN
// or Inf in any written map, every value within its U3M range, a U3M that passes validation, the
// affected parameters bounded against the truth or flagged "not measured", and the ill-conditioned
// pixels counted in report.json. Inputs that cannot give a material are refused with an
// InputError that names the file, and nothing is written.
//
// Captures are tiny (32x32 camera pixels, a 28x28 scene) and rendered as TIFF without calibration
// frames unless the case needs them, so the binary runs in seconds.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <iostream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "capture/manifest.h"
#include "core/error.h"
#include "datasets_synthetic/capture_writer.h"
#include "datasets_synthetic/rig.h"
#include "datasets_synthetic/scene.h"
#include "pipeline/process.h"
#include "tests/support/bump_scene.h"
#include "u3m/image_io.h"
#include "u3m/validate.h"

namespace u3mscan {
namespace {

namespace fs = std::filesystem;
using synthetic::SceneTruth;

// Sizes: camera pixels and scene grid (the scene is smaller than the view, the table shows around it).
constexpr int kCameraPixels = 32;
constexpr int kScenePixels = 28;
constexpr double kBumpAmplitudeMm = 0.05;
constexpr double kBumpPeriodMm = 1.5;
constexpr double kPartlySaturatingGain = 2.0;  // light intensity factor: part of the frames clip
constexpr double kOverexposingGain = 8.0;      // every pixel clips under nearly every light

// Tolerances.
constexpr double kUnitNormalTolerance = 1e-3;     // |n| - 1 in the debug normal map
constexpr double kRangeSlack = 1e-5;              // float rounding at the ends of 0..1
// Stability bound of a measured Principled parameter: |fitted - truth| below a third of its 0..1
// range. It catches values pinned at a bound or blown up while reported as measured; the accuracy
// targets of issue 6 (roughness 0.05, specular 0.1) belong to the benchmark, not to this suite.
constexpr double kParameterStabilityBound = 0.3;
constexpr double kHeightRangeFactor = 2.0;        // displacement range within [truth / 2, truth * 2]
constexpr double kMaxAlbedo = 1.5;                // photometric-stereo albedo: >= 0, plausible, not clamped
constexpr double kBaseColourRelativeTolerance = 0.2;  // relative error of the mean base colour
constexpr double kMeanNormalToleranceDeg = 5.0;   // mean normal of a bump field vs +z

const char* const kFixedId = "3f2c1a9e-8b7d-4c6e-9a5f-0123456789ab";
const char* const kFixedCreated = "2026-11-22T10:00:00Z";

// ---------------------------------------------------------------------------------------------
// Scenes (built in code: the bump field of the pipeline's end-to-end test, varied per extreme).

SceneTruth Scene(const std::string& kind) {
  SceneTruth scene = testing::BumpScene(kScenePixels, kScenePixels, 25.4 / 300.0, kBumpAmplitudeMm, kBumpPeriodMm);
  scene.name = kind;
  auto fill = [](Image& image, std::vector<float> values) {
    for (int c = 0; c < image.channels(); ++c) std::fill(image.plane(c).begin(), image.plane(c).end(), values[c]);
  };
  if (kind == "plain") {
    // The bump field as it is: roughness 0.6, specular 0.5, base colour (0.6, 0.4, 0.3).
  } else if (kind == "dark") {
    fill(scene.base_color, {0.01f, 0.008f, 0.006f});  // near-black fabric: signal close to the noise floor
  } else if (kind == "bright") {
    fill(scene.base_color, {0.95f, 0.95f, 0.95f});  // with lights x4 (see SaturatingRig) most frames clip
  } else if (kind == "mirror") {
    fill(scene.roughness, {0.02f});
    fill(scene.specular, {1.0f});
  } else if (kind == "pure_velvet") {
    fill(scene.base_color, {0.05f, 0.01f, 0.02f});
    fill(scene.roughness, {1.0f});
    fill(scene.specular, {0.0f});
    fill(scene.sheen, {1.0f});
    fill(scene.sheen_tint, {0.0f});
  } else if (kind == "holes") {
    // Square holes on a 7-pixel lattice: 3x3 pixels of every 7x7 cell are open.
    for (int row = 0; row < kScenePixels; ++row) {
      for (int col = 0; col < kScenePixels; ++col) {
        if (row % 7 >= 2 && row % 7 < 5 && col % 7 >= 2 && col % 7 < 5) {
          scene.alpha.at(0, row, col) = 0.0f;
          scene.height_mm.at(0, row, col) = 0.0f;
          scene.normal.at(0, row, col) = 0.0f;
          scene.normal.at(1, row, col) = 0.0f;
          scene.normal.at(2, row, col) = 1.0f;
        }
      }
    }
  } else {
    throw std::invalid_argument("unknown stability scene " + kind);
  }
  return scene;
}

struct TruthValues {
  double roughness, specular, sheen;
  double base_luminance;  // mean of base colour channels
};

// Means over the fabric (alpha-weighted: holes carry no material), over all channels.
TruthValues TruthOf(const SceneTruth& scene) {
  auto mean = [&](const Image& image) {
    double sum = 0, weight = 0;
    const auto alpha = scene.alpha.plane(0);
    for (int c = 0; c < image.channels(); ++c) {
      const auto values = image.plane(c);
      for (std::size_t i = 0; i < values.size(); ++i) {
        sum += static_cast<double>(alpha[i]) * values[i];
        weight += alpha[i];
      }
    }
    return weight > 0 ? sum / weight : 0.0;
  };
  return {mean(scene.roughness), mean(scene.specular), mean(scene.sheen), mean(scene.base_color)};
}

// ---------------------------------------------------------------------------------------------
// Captures and runs.

struct Outcome {
  fs::path out;
  fs::path material;
  nlohmann::json report;
};

class StabilityTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    std::string name = info->name();  // "Case" or "Case/3" for parameterised cases
    std::replace(name.begin(), name.end(), '/', '_');
    root_ = fs::temp_directory_path() / ("u3mscan_stability_" + name);
    fs::remove_all(root_);
    fs::create_directories(root_);
  }
  void TearDown() override {
    if (!std::getenv("U3MSCAN_KEEP_TEST_OUTPUT")) fs::remove_all(root_);
  }

  // Writes a synthetic capture and returns its capture folder.
  fs::path MakeCapture(const SceneTruth& scene, const std::string& rig_name, bool calibration_frames = false,
                       const std::function<void(synthetic::Rig&)>& edit_rig = {}) {
    synthetic::RigOptions rig_options;
    rig_options.width = kCameraPixels;
    rig_options.height = kCameraPixels;
    synthetic::Rig rig = synthetic::MakeRig(rig_name, rig_options);
    if (edit_rig) edit_rig(rig);
    synthetic::CaptureOptions options;
    options.format = synthetic::FrameFormat::kTiff;
    options.calibration_frames = calibration_frames;
    const fs::path dir = root_ / "synthetic";
    synthetic::WriteSyntheticCapture(scene, rig, options, dir);
    return dir / synthetic::kCaptureSubdir;
  }

  Outcome Process(const fs::path& capture, Preset preset = Preset::kFast) {
    Outcome run;
    run.out = root_ / "out";
    CaptureJob job{capture, run.out, "sample"};
    ProcessOptions options;
    options.preset = preset;
    options.debug_maps = true;
    options.id = kFixedId;
    options.created = kFixedCreated;
    const ProcessResult result = ProcessCapture(job, options);
    run.material = result.material;
    std::ifstream in(run.out / "report.json");
    run.report = nlohmann::json::parse(in);
    return run;
  }

  // Runs and expects an InputError naming a file, with nothing written into the output folder.
  void ExpectRefused(const fs::path& capture, const std::string& file_part) {
    const fs::path out = root_ / "out";
    CaptureJob job{capture, out, "sample"};
    ProcessOptions options;
    options.preset = Preset::kFast;
    options.debug_maps = true;
    try {
      ProcessCapture(job, options);
      ADD_FAILURE() << "expected an InputError for " << capture;
    } catch (const InputError& error) {
      std::cout << "[ REFUSED  ] " << error.what() << "\n";
      EXPECT_NE(error.file().find(file_part), std::string::npos) << error.what();
      EXPECT_FALSE(error.expected().empty()) << error.what();
    }
    std::error_code ec;
    const bool empty = !fs::exists(out, ec) || fs::is_empty(out, ec);
    EXPECT_TRUE(empty) << "a refused capture must write nothing into " << out;
  }

  fs::path root_;
};

// ---------------------------------------------------------------------------------------------
// Checks.

// A U3M writes null for "no texture" and for an absent back side; anywhere else a null is a
// NaN or Inf that nlohmann::json wrote as null.
bool NullAllowed(const std::string& pointer) {
  return pointer.size() >= 8 && (pointer.compare(pointer.size() - 8, 8, "/texture") == 0 ||
                                 pointer.compare(pointer.size() - 5, 5, "/back") == 0);
}

void ExpectNoNull(const nlohmann::json& j, const std::string& pointer) {
  if (j.is_null()) {
    if (NullAllowed(pointer)) return;
    ADD_FAILURE() << pointer << " is null (a NaN or Inf written to JSON)";
  } else if (j.is_object()) {
    for (auto it = j.begin(); it != j.end(); ++it) ExpectNoNull(it.value(), pointer + "/" + it.key());
  } else if (j.is_array()) {
    for (std::size_t i = 0; i < j.size(); ++i) ExpectNoNull(j[i], pointer + "/" + std::to_string(i));
  } else if (j.is_number_float()) {
    EXPECT_TRUE(std::isfinite(j.get<double>())) << pointer;
  }
}

// Counts non-finite values and values outside [lo, hi] over all channels.
void ExpectFiniteInRange(const Image& image, double lo, double hi, const std::string& what) {
  std::size_t non_finite = 0, out_of_range = 0;
  float min_seen = INFINITY, max_seen = -INFINITY;
  for (float v : image.data()) {
    if (!std::isfinite(v)) {
      ++non_finite;
      continue;
    }
    min_seen = std::min(min_seen, v);
    max_seen = std::max(max_seen, v);
    if (v < lo - kRangeSlack || v > hi + kRangeSlack) ++out_of_range;
  }
  EXPECT_EQ(non_finite, 0u) << what << ": NaN or Inf values";
  EXPECT_EQ(out_of_range, 0u) << what << ": values in [" << min_seen << ", " << max_seen << "], expected [" << lo
                              << ", " << hi << "]";
}

// Range of each debug map by file name (maps/<name>.exr, prefixed "back_" for the back side).
void CheckDebugMap(const fs::path& path) {
  const Image image = ReadImageFile(path, PixelEncoding::kLinear);
  std::string name = path.stem().string();
  if (name.rfind("back_", 0) == 0) name = name.substr(5);
  const std::string what = path.filename().string();
  if (name == "normal") {
    ExpectFiniteInRange(image, -1.0, 1.0, what);
    std::size_t not_unit = 0;
    for (std::size_t i = 0; i < image.pixel_count(); ++i) {
      const double x = image.plane(0)[i], y = image.plane(1)[i], z = image.plane(2)[i];
      if (std::abs(std::sqrt(x * x + y * y + z * z) - 1.0) > kUnitNormalTolerance || z < 0) ++not_unit;
    }
    EXPECT_EQ(not_unit, 0u) << what << ": normals that are not unit or face away from the camera";
  } else if (name == "height" ) {
    ExpectFiniteInRange(image, -1e3, 1e3, what);  // mm: finite and physically plausible
  } else if (name == "albedo") {
    ExpectFiniteInRange(image, 0.0, kMaxAlbedo, what);
  } else if (name == "base_color") {
    ExpectFiniteInRange(image, 0.0, 1.0, what);
  } else if (name == "residual") {
    ExpectFiniteInRange(image, 0.0, 1e6, what);
  } else if (name == "anisotropy_rotation") {
    ExpectFiniteInRange(image, 0.0, 180.0, what);  // degrees over the half turn the stretch repeats in
  } else {
    // confidence and every fitted Principled parameter live in 0..1.
    ExpectFiniteInRange(image, 0.0, 1.0, what);
  }
}

// The entry of `name` ("front/roughness") in the material's custom section "parameter_sources".
const nlohmann::json* MaterialParameterSource(const fs::path& material, const std::string& name) {
  static nlohmann::json u3m;  // kept alive for the returned pointer (one test at a time)
  std::ifstream in(material);
  u3m = nlohmann::json::parse(in);
  if (!u3m.contains("custom") || !u3m["custom"].is_object()) return nullptr;
  for (auto& section : u3m["custom"]) {
    if (section.is_object() && section.contains("parameter_sources") && section["parameter_sources"].contains(name)) {
      return &section["parameter_sources"][name];
    }
  }
  return nullptr;
}

// Everything a successful run must satisfy whatever the input.
void ExpectSaneOutput(const fs::path& out, const fs::path& material, const nlohmann::json& report) {
  ASSERT_TRUE(fs::exists(material));
  const ValidationReport validation = ValidateMaterialFile(material);
  for (const auto& issue : validation.issues) {
    if (issue.severity == IssueSeverity::kError) ADD_FAILURE() << issue.pointer << ": " << issue.message;
  }
  EXPECT_TRUE(validation.valid());
  {
    // The material's own values (the custom section's calibration record uses null for "absent").
    std::ifstream in(material);
    nlohmann::json u3m = nlohmann::json::parse(in);
    for (auto it = u3m.begin(); it != u3m.end(); ++it) {
      if (it.key() != "custom") ExpectNoNull(it.value(), material.filename().string() + "/" + it.key());
    }
  }
  // Textures: integer PNG, so read back they are in 0..1 by construction; NaN would have been
  // quantised to 0 silently, so the debug maps below are the real NaN check.
  int textures = 0;
  if (fs::exists(out / "textures")) {
    for (const auto& entry : fs::directory_iterator(out / "textures")) {
      const Image image = ReadImageFile(entry.path(), PixelEncoding::kLinear);
      ExpectFiniteInRange(image, 0.0, 1.0, entry.path().filename().string());
      ++textures;
    }
  }
  int maps = 0;
  for (const auto& entry : fs::directory_iterator(out / "maps")) {
    if (entry.path().extension() == ".exr") {
      CheckDebugMap(entry.path());
      ++maps;
    }
  }
  EXPECT_GE(maps, 4) << "normal, albedo, height and confidence debug maps expected";

  EXPECT_EQ(report.value("status", ""), "ok");
  ExpectNoNull(report["quality"], "report.json/quality");
  ExpectNoNull(report["parameters"], "report.json/parameters");
  ASSERT_TRUE(report.contains("quality"));
  ASSERT_TRUE(report["quality"].contains("front"));
  const auto& front = report["quality"]["front"];
  for (const char* key : {"ill_conditioned_pixels", "dark_pixels", "regularised_pixels"}) {
    ASSERT_TRUE(front.contains(key) && front[key].is_number_integer()) << key;
    EXPECT_GE(front[key].get<long long>(), 0) << key;
  }
  const double confidence = front["mean_confidence"].get<double>();
  EXPECT_GE(confidence, 0.0);
  EXPECT_LE(confidence, 1.0);
  // Every parameter says where its value comes from; not-measured ones say why.
  for (const auto& p : report["parameters"]) {
    EXPECT_FALSE(p["source"].get<std::string>().empty()) << p.dump();
    EXPECT_FALSE(p["reason"].get<std::string>().empty()) << p.dump();
    // Every parameter carries a reliability verdict; a flagged one says why, and the material's own
    // custom section ("what each parameter's value comes from") carries the same flag.
    ASSERT_TRUE(p.contains("reliable") && p["reliable"].is_boolean()) << p.dump();
    if (!p["reliable"].get<bool>()) {
      EXPECT_FALSE(p.value("unreliable_reason", std::string()).empty()) << p.dump();
      const nlohmann::json* source = MaterialParameterSource(material, p["name"].get<std::string>());
      ASSERT_NE(source, nullptr) << p["name"] << " flagged in report.json but not listed in the material's custom section";
      EXPECT_FALSE(source->value("reliable", true)) << source->dump();
    }
  }
}

const nlohmann::json* FindParameter(const nlohmann::json& report, const std::string& name) {
  for (const auto& p : report["parameters"]) {
    if (p["name"] == name) return &p;
  }
  return nullptr;
}

bool IsNotMeasured(const nlohmann::json& p) {
  return p["source"].get<std::string>() == ParameterSourceName(ParameterSource::kDefault);
}

bool IsFlaggedUnreliable(const nlohmann::json& p) { return !p.value("reliable", true); }

// The parameter is within `tolerance` of the truth, or the report does not vouch for it: not
// measured (U3M default, with a reason) or measured but flagged unreliable (with a reason). A wrong
// value reported as reliable fails.
void ExpectBoundedOrFlagged(const nlohmann::json& report, const std::string& name, double truth, double tolerance) {
  const nlohmann::json* p = FindParameter(report, name);
  ASSERT_NE(p, nullptr) << name << " missing from report.json parameters";
  if (IsNotMeasured(*p)) {
    EXPECT_FALSE((*p)["reason"].get<std::string>().empty()) << name;
    return;
  }
  const double value = (*p)["value"].get<double>();
  if (std::abs(value - truth) <= tolerance) return;
  EXPECT_TRUE(IsFlaggedUnreliable(*p)) << name << " = " << value << " (truth " << truth << ") is off by more than "
                                       << tolerance << " and reported as reliable: " << p->dump();
  std::cout << "[ FLAGGED  ] " << name << " = " << value << " (truth " << truth
            << "): " << p->value("unreliable_reason", std::string()) << "\n";
}

long long Quality(const nlohmann::json& report, const char* key) {
  return report["quality"]["front"][key].get<long long>();
}

std::size_t GridPixels(const fs::path& out) {
  const ImageReadInfo info = ReadImageInfo(out / "maps" / "normal.exr");
  return static_cast<std::size_t>(info.width) * info.height;
}

// Mean of the centre half of a debug map (the sample; the table shows around it).
std::vector<double> CentreMean(const fs::path& path) {
  const Image image = ReadImageFile(path, PixelEncoding::kLinear);
  std::vector<double> mean(image.channels(), 0.0);
  const int r0 = image.height() / 4, r1 = image.height() - r0, c0 = image.width() / 4, c1 = image.width() - c0;
  for (int c = 0; c < image.channels(); ++c) {
    for (int row = r0; row < r1; ++row) {
      for (int col = c0; col < c1; ++col) mean[c] += image.at(c, row, col);
    }
    mean[c] /= static_cast<double>((r1 - r0) * (c1 - c0));
  }
  return mean;
}

// Height: the displacement's range (report.json, mm) within a factor of the truth's, unless the
// report flags the displacement unreliable (the reconstruction's own evidence: guessed slopes, low
// confidence).
void ExpectHeightBoundedOrFlagged(const nlohmann::json& report, const SceneTruth& scene) {
  float lo = INFINITY, hi = -INFINITY;
  for (float h : scene.height_mm.plane(0)) {
    lo = std::min(lo, h);
    hi = std::max(hi, h);
  }
  const nlohmann::json* p = FindParameter(report, "front/displacement");
  ASSERT_NE(p, nullptr);
  const double range_mm = (*p)["value"].get<double>();  // 0 when written flat
  if (range_mm > (hi - lo) / kHeightRangeFactor && range_mm < (hi - lo) * kHeightRangeFactor) return;
  EXPECT_TRUE(IsFlaggedUnreliable(*p)) << "height range " << range_mm << " mm (truth " << hi - lo
                                       << " mm) reported as reliable: " << p->dump();
  std::cout << "[ FLAGGED  ] height range " << range_mm << " mm (truth " << hi - lo
            << " mm): " << p->value("unreliable_reason", std::string()) << "\n";
}

void ExpectTruthBounds(const Outcome& run, const SceneTruth& scene) {
  const TruthValues truth = TruthOf(scene);
  ExpectHeightBoundedOrFlagged(run.report, scene);
  ExpectBoundedOrFlagged(run.report, "front/roughness", truth.roughness, kParameterStabilityBound);
  ExpectBoundedOrFlagged(run.report, "front/specular_value", truth.specular, kParameterStabilityBound);
  ExpectBoundedOrFlagged(run.report, "front/sheen_value", truth.sheen, kParameterStabilityBound);
}

// ---------------------------------------------------------------------------------------------
// Extreme presets of the synthetic scanner.

TEST_F(StabilityTest, PlainSceneOnDistantRigMatchesTruth) {
  const SceneTruth scene = Scene("plain");
  const Outcome run = Process(MakeCapture(scene, "distant"));
  ExpectSaneOutput(run.out, run.material, run.report);
  ExpectTruthBounds(run, scene);
  // Base colour (fit) and mean normal of the sample's centre against the truth.
  const fs::path base = fs::exists(run.out / "maps" / "base_color.exr") ? run.out / "maps" / "base_color.exr"
                                                                         : run.out / "maps" / "albedo.exr";
  const std::vector<double> colour = CentreMean(base);
  const TruthValues truth = TruthOf(scene);
  const double luminance = (colour[0] + colour[1] + colour[2]) / 3.0;
  EXPECT_NEAR(luminance, truth.base_luminance, kBaseColourRelativeTolerance * truth.base_luminance);
  const std::vector<double> n = CentreMean(run.out / "maps" / "normal.exr");
  const double angle_deg = std::acos(n[2] / std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2])) * 180.0 / M_PI;
  EXPECT_LT(angle_deg, kMeanNormalToleranceDeg);
}

TEST_F(StabilityTest, GrazingLights) {
  const SceneTruth scene = Scene("plain");
  const Outcome run = Process(MakeCapture(scene, "grazing"));
  ExpectSaneOutput(run.out, run.material, run.report);
  ExpectTruthBounds(run, scene);
}

TEST_F(StabilityTest, NearlyCoplanarLightsAreCountedIllConditioned) {
  const SceneTruth scene = Scene("plain");
  const Outcome run = Process(MakeCapture(scene, "coplanar"));
  ExpectSaneOutput(run.out, run.material, run.report);
  ExpectTruthBounds(run, scene);
  // Every light lies within ~0.5 deg of the x-z plane: the y component of every normal is
  // poorly determined, so (nearly) every pixel's light system is ill-conditioned.
  EXPECT_GT(Quality(run.report, "ill_conditioned_pixels"), static_cast<long long>(GridPixels(run.out) / 2));
}

TEST_F(StabilityTest, SingleUsableLightPerPixel) {
  const SceneTruth scene = Scene("plain");
  const Outcome run = Process(MakeCapture(scene, "single_light"));
  ExpectSaneOutput(run.out, run.material, run.report);
  ExpectTruthBounds(run, scene);
  EXPECT_GT(Quality(run.report, "ill_conditioned_pixels") + Quality(run.report, "dark_pixels"), 0);
  // Most pixels see one light: their slopes are guessed, so the height is flagged whatever range it
  // happens to come out at (0.14-0.21 mm for a truth of 0.10 mm, depending on the normals).
  const nlohmann::json* height = FindParameter(run.report, "front/displacement");
  ASSERT_NE(height, nullptr);
  EXPECT_TRUE(IsFlaggedUnreliable(*height)) << height->dump();
}

TEST_F(StabilityTest, HeavyNoise) {
  const SceneTruth scene = Scene("plain");
  const Outcome run = Process(MakeCapture(scene, "noisy"));
  ExpectSaneOutput(run.out, run.material, run.report);
  ExpectTruthBounds(run, scene);
}

TEST_F(StabilityTest, VeryDarkSample) {
  const SceneTruth scene = Scene("dark");
  const Outcome run = Process(MakeCapture(scene, "distant"));
  ExpectSaneOutput(run.out, run.material, run.report);
  ExpectTruthBounds(run, scene);
}

TEST_F(StabilityTest, SaturatingSample) {
  const SceneTruth scene = Scene("bright");
  // Twice the light: a white sample clips in part of the frames.
  const Outcome run = Process(MakeCapture(scene, "distant", false, [](synthetic::Rig& rig) {
    for (auto& light : rig.lights) light.intensity_rgb *= kPartlySaturatingGain;
  }));
  ExpectSaneOutput(run.out, run.material, run.report);
  ExpectTruthBounds(run, scene);
}

TEST_F(StabilityTest, OverexposedCaptureIsRefused) {
  // Eight times the light: every pixel clips under nearly every light; nothing can be measured.
  const fs::path capture = MakeCapture(Scene("bright"), "distant", false, [](synthetic::Rig& rig) {
    for (auto& light : rig.lights) light.intensity_rgb *= kOverexposingGain;
  });
  ExpectRefused(capture, "capture.json");
}

TEST_F(StabilityTest, NearMirrorRoughness) {
  const SceneTruth scene = Scene("mirror");
  const Outcome run = Process(MakeCapture(scene, "distant"));
  ExpectSaneOutput(run.out, run.material, run.report);
  ExpectTruthBounds(run, scene);
}

TEST_F(StabilityTest, PureVelvet) {
  const SceneTruth scene = Scene("pure_velvet");
  const Outcome run = Process(MakeCapture(scene, "distant"));
  ExpectSaneOutput(run.out, run.material, run.report);
  ExpectTruthBounds(run, scene);
  // Only an overhead camera: sheen cannot be observed and must be left out, saying why.
  const nlohmann::json* sheen = FindParameter(run.report, "front/sheen_value");
  ASSERT_NE(sheen, nullptr);
  EXPECT_TRUE(IsNotMeasured(*sheen)) << sheen->dump();
  EXPECT_NE((*sheen)["reason"].get<std::string>().find("oblique"), std::string::npos) << sheen->dump();
}

TEST_F(StabilityTest, HolesGiveAnAlphaMapAndNoNaN) {
  const SceneTruth scene = Scene("holes");
  const Outcome run = Process(MakeCapture(scene, "distant", /*calibration_frames=*/true));
  ExpectSaneOutput(run.out, run.material, run.report);
  ExpectTruthBounds(run, scene);
  EXPECT_TRUE(fs::exists(run.out / "textures" / "front_alpha.png")) << "holes must give an alpha texture";
}

// The synthetic scanner's own extreme scene presets (datasets_synthetic/scene.h: woven geometry,
// per-thread variation) on the distant rig: the same checks, truth from the scene's maps.
class ScannerPresetTest : public StabilityTest, public ::testing::WithParamInterface<const char*> {};

TEST_P(ScannerPresetTest, SaneAndBoundedOrFlagged) {
  synthetic::SceneOptions scene_options;
  scene_options.width = kScenePixels;
  scene_options.height = kScenePixels;
  const SceneTruth scene = synthetic::MakeScene(GetParam(), scene_options);
  const bool holes = std::string(GetParam()) == "holes";  // the backlight frame is a calibration frame
  const Outcome run = Process(MakeCapture(scene, "distant", holes));
  ExpectSaneOutput(run.out, run.material, run.report);
  const TruthValues truth = TruthOf(scene);
  ExpectBoundedOrFlagged(run.report, "front/roughness", truth.roughness, kParameterStabilityBound);
  ExpectBoundedOrFlagged(run.report, "front/specular_value", truth.specular, kParameterStabilityBound);
  ExpectBoundedOrFlagged(run.report, "front/sheen_value", truth.sheen, kParameterStabilityBound);
}

INSTANTIATE_TEST_SUITE_P(Extremes, ScannerPresetTest,
                         ::testing::Values("dark", "bright", "mirror", "pure_velvet", "holes"));

// ---------------------------------------------------------------------------------------------
// Degenerate inputs, made by editing a tiny synthetic capture.

// Reads, edits and rewrites capture.json.
void EditManifest(const fs::path& capture, const std::function<void(Manifest&)>& edit) {
  Manifest manifest = ReadManifest(capture);
  edit(manifest);
  WriteManifest(manifest, capture);
}

std::vector<std::size_t> SampleFrames(const Manifest& manifest) {
  std::vector<std::size_t> out;
  for (std::size_t i = 0; i < manifest.frames.size(); ++i) {
    if (manifest.frames[i].role == FrameRole::kSample) out.push_back(i);
  }
  return out;
}

void WriteFrame(const Image& image, const fs::path& path) {
  ImageWriteOptions options;
  options.format = SampleFormat::kUInt16;
  WriteImageFile(image, path, options);
}

// Box-averages every frame of the capture down to width x height and scales the intrinsics to match.
void ShrinkCapture(const fs::path& capture, int width, int height) {
  EditManifest(capture, [&](Manifest& manifest) {
    for (auto& camera : manifest.cameras) {
      const double sx = static_cast<double>(width) / camera.width, sy = static_cast<double>(height) / camera.height;
      camera.intrinsics.fx *= sx;
      camera.intrinsics.fy *= sy;
      camera.intrinsics.cx = (camera.intrinsics.cx + 0.5) * sx - 0.5;
      camera.intrinsics.cy = (camera.intrinsics.cy + 0.5) * sy - 0.5;
      camera.width = width;
      camera.height = height;
    }
    for (const auto& frame : manifest.frames) {
      const fs::path path = capture / frame.file;
      const Image full = ReadImageFile(path, PixelEncoding::kLinear);
      Image small(width, height, full.channels(), 0.0f, full.pitch_mm());
      for (int c = 0; c < full.channels(); ++c) {
        for (int row = 0; row < full.height(); ++row) {
          for (int col = 0; col < full.width(); ++col) {
            small.at(c, row * height / full.height(), col * width / full.width()) += full.at(c, row, col);
          }
        }
      }
      const float cells = static_cast<float>(full.width() * full.height()) / static_cast<float>(width * height);
      for (float& v : small.data()) v /= cells;
      WriteFrame(small, path);
    }
  });
}

TEST_F(StabilityTest, OneAllBlackFrame) {
  const fs::path capture = MakeCapture(Scene("plain"), "distant");
  const Manifest manifest = ReadManifest(capture);
  const FrameSpec& frame = manifest.frames[SampleFrames(manifest).front()];
  WriteFrame(Image(kCameraPixels, kCameraPixels, 3, 0.0f), capture / frame.file);
  const Outcome run = Process(capture);
  ExpectSaneOutput(run.out, run.material, run.report);
  ExpectTruthBounds(run, Scene("plain"));
  // The black frame is left out with a warning naming its light.
  bool warned = false;
  for (const auto& warning : run.report["warnings"]) {
    const std::string text = warning.get<std::string>();
    warned = warned || (text.find("no signal") != std::string::npos && text.find(*frame.light) != std::string::npos);
  }
  EXPECT_TRUE(warned) << run.report["warnings"].dump(1);
}

TEST_F(StabilityTest, EveryFrameBlackIsRefused) {
  const fs::path capture = MakeCapture(Scene("plain"), "distant");
  const Manifest manifest = ReadManifest(capture);
  for (const FrameSpec& frame : manifest.frames) WriteFrame(Image(kCameraPixels, kCameraPixels, 3, 0.0f), capture / frame.file);
  // Nothing to measure: the pipeline must not invent a material from nothing.
  ExpectRefused(capture, "capture.json");
}

TEST_F(StabilityTest, OneFrameIsRefused) {
  const fs::path capture = MakeCapture(Scene("plain"), "distant");
  EditManifest(capture, [](Manifest& manifest) {
    const std::vector<std::size_t> samples = SampleFrames(manifest);
    for (auto it = samples.rbegin(); it != samples.rend() - 1; ++it) {
      manifest.frames.erase(manifest.frames.begin() + static_cast<std::ptrdiff_t>(*it));
    }
  });
  ExpectRefused(capture, "capture.json");
}

TEST_F(StabilityTest, TwoIdenticalLights) {
  const fs::path capture = MakeCapture(Scene("plain"), "distant");
  EditManifest(capture, [&](Manifest& manifest) {
    const std::vector<std::size_t> samples = SampleFrames(manifest);
    const FrameSpec& a = manifest.frames[samples[0]];
    const FrameSpec& b = manifest.frames[samples[1]];
    LightSpec* la = nullptr;
    LightSpec* lb = nullptr;
    for (auto& light : manifest.lights) {
      if (light.id == *a.light) la = &light;
      if (light.id == *b.light) lb = &light;
    }
    ASSERT_TRUE(la && lb);
    lb->direction = la->direction;
    lb->position_mm = la->position_mm;
    lb->intensity_rgb = la->intensity_rgb;
    fs::copy_file(capture / a.file, capture / b.file, fs::copy_options::overwrite_existing);
  });
  const Outcome run = Process(capture);
  ExpectSaneOutput(run.out, run.material, run.report);
  ExpectTruthBounds(run, Scene("plain"));
}

TEST_F(StabilityTest, OnePixelImageIsRefused) {
  const fs::path capture = MakeCapture(Scene("plain"), "distant");
  ShrinkCapture(capture, 1, 1);
  ExpectRefused(capture, "capture.json");
}

TEST_F(StabilityTest, ThreeByTwoImageGivesASaneMaterial) {
  // Six pixels are few but enough for photometric stereo and a constant fit: a tiny material.
  const fs::path capture = MakeCapture(Scene("plain"), "distant");
  ShrinkCapture(capture, 3, 2);
  const Outcome run = Process(capture);
  ExpectSaneOutput(run.out, run.material, run.report);
}

// ---------------------------------------------------------------------------------------------
// Leave out what a scene does not need: skipped steps listed with their reason.

const nlohmann::json* FindStep(const nlohmann::json& report, const std::string& prefix) {
  for (const auto& step : report["steps"]) {
    if (step["name"].get<std::string>().rfind(prefix, 0) == 0) return &step;
  }
  return nullptr;
}

void ExpectSkipped(const nlohmann::json& report, const std::string& step, const std::string& reason_part) {
  const nlohmann::json* s = FindStep(report, step);
  ASSERT_NE(s, nullptr) << "no step '" << step << "' in report.json: " << report["steps"].dump(1);
  EXPECT_FALSE((*s)["ran"].get<bool>()) << s->dump();
  EXPECT_NE((*s)["reason"].get<std::string>().find(reason_part), std::string::npos) << s->dump();
}

TEST_F(StabilityTest, SimpleCaptureListsSkippedSteps) {
  // Distant lights, one camera, front only, no chart (no calibration frames at all).
  const Outcome run = Process(MakeCapture(Scene("plain"), "distant"));
  ExpectSkipped(run.report, "calibration: colour", "chart");
  ExpectSkipped(run.report, "back side", "back");
  ExpectSkipped(run.report, "near-light refinement", "distant");
  ExpectSkipped(run.report, "oblique view", "camera");
}

TEST_F(StabilityTest, ObliqueNearCaptureRunsWhatItNeeds) {
  // Near point lights and an oblique camera: the near-light refinement replaces the separate
  // integration, and the oblique view is used.
  const Outcome run = Process(MakeCapture(Scene("plain"), "oblique"));
  ExpectSaneOutput(run.out, run.material, run.report);
  ExpectSkipped(run.report, "integration", "near-light");
  EXPECT_EQ(FindStep(run.report, "near-light refinement"), nullptr);
  const nlohmann::json* oblique = FindStep(run.report, "oblique view");
  if (oblique) {
    EXPECT_TRUE((*oblique)["ran"].get<bool>()) << oblique->dump();
  }
}

}  // namespace
}  // namespace u3mscan
