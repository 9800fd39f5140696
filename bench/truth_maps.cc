#include "bench/truth_maps.h"

#include <fstream>

#include <nlohmann/json.hpp>

#include "core/error.h"
#include "u3m/image_io.h"

namespace u3mscan::bench {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

constexpr const char* kParameterKeys[7] = {"roughness",  "specular",    "specular_tint", "sheen",
                                           "sheen_tint", "anisotropic", "metallic"};

}  // namespace

TruthMaps ReadTruthMaps(const fs::path& truth_dir) {
  const fs::path truth_file = truth_dir / "truth.json";
  std::ifstream in(truth_file);
  if (!in) throw InputError(truth_file.string(), "", "a readable truth.json of a synthetic capture");
  json truth;
  try {
    truth = json::parse(in);
  } catch (const json::exception& e) {
    throw InputError(truth_file.string(), "", std::string("valid JSON: ") + e.what());
  }
  if (!truth.is_object()) throw InputError(truth_file.string(), "", "a JSON object");
  const json maps = truth.contains("maps") && truth["maps"].is_object() ? truth["maps"] : json::object();
  auto file_of = [&](const std::string& key) -> fs::path {
    if (maps.contains(key) && maps[key].is_string()) return truth_dir / maps[key].get<std::string>();
    return truth_dir / (key + ".exr");
  };
  auto read = [&](const std::string& key, bool required) -> Image {
    const fs::path path = file_of(key);
    if (!fs::exists(path)) {
      if (required) throw InputError(path.string(), "", "the truth map '" + key + "' (listed in truth.json /maps or named " + key + ".exr)");
      return {};
    }
    return ReadImageFile(path, PixelEncoding::kLinear);
  };
  TruthMaps t;
  t.scene = truth.value("scene", std::string());
  if (truth.contains("reflectance_model")) {
    const json& model = truth["reflectance_model"];
    if (!model.is_string() || !synthetic::ParseReflectanceModel(model.get<std::string>(), &t.model)) {
      throw InputError(truth_file.string(), "/reflectance_model", synthetic::ReflectanceModelChoices());
    }
  }
  t.height_mm = read("height_mm", true);
  t.normal = read("normal", true);
  t.base_color = read("base_color", true);
  t.alpha = read("alpha", false);
  t.tangent = read("tangent", false);
  if (!t.tangent.empty() && (t.tangent.channels() < 3 || t.tangent.width() != t.height_mm.width() ||
                             t.tangent.height() != t.height_mm.height())) {
    t.tangent = Image();  // unusable: fall back to the +x convention
  }
  for (int p = 0; p < 7; ++p) t.parameters[p] = read(kParameterKeys[p], false);
  if (t.normal.channels() < 3 || t.base_color.channels() < 3) {
    throw InputError(file_of("normal").string(), "", "3-channel normal and base colour truth maps");
  }
  if (t.normal.width() != t.height_mm.width() || t.normal.height() != t.height_mm.height() ||
      t.base_color.width() != t.height_mm.width() || t.base_color.height() != t.height_mm.height()) {
    throw InputError(file_of("normal").string(), "", "truth maps of one size (the scene grid)");
  }

  // Pitch and placement: the capture writer's "rig" section wins (it is where the scene was rendered).
  const json* rig = truth.contains("rig") && truth["rig"].is_object() ? &truth["rig"] : nullptr;
  t.pitch_mm = truth.value("pitch_mm", 0.0);
  if (truth.contains("grid") && truth["grid"].is_object() && truth["grid"].contains("pitch_mm") &&
      truth["grid"]["pitch_mm"].is_number()) {
    t.pitch_mm = truth["grid"]["pitch_mm"].get<double>();  // WriteTruth's grid
  }
  if (rig && (*rig).contains("sample_pitch_mm") && (*rig)["sample_pitch_mm"].is_number()) {
    t.pitch_mm = (*rig)["sample_pitch_mm"].get<double>();
  }
  if (!(t.pitch_mm > 0.0)) throw InputError(truth_file.string(), "/rig/sample_pitch_mm", "a positive pitch in mm");
  const double w_mm = t.height_mm.width() * t.pitch_mm, h_mm = t.height_mm.height() * t.pitch_mm;
  t.x0_mm = -0.5 * w_mm;
  t.y1_mm = 0.5 * h_mm;
  if (rig && (*rig).contains("sample_rect_mm")) {
    const json& rect = (*rig)["sample_rect_mm"];
    if (!rect.is_array() || rect.size() != 4 || !rect[0].is_number() || !rect[3].is_number()) {
      throw InputError(truth_file.string(), "/rig/sample_rect_mm", "[x0, y0, x1, y1] in mm");
    }
    t.x0_mm = rect[0].get<double>();
    t.y1_mm = rect[3].get<double>();
  }
  return t;
}

}  // namespace u3mscan::bench
