#include "datasets_synthetic/truth_writer.h"

#include <atomic>
#include <chrono>
#include <fstream>
#include <stdexcept>
#include <string>
#include <system_error>
#include <utility>
#include <vector>

#include "core/error.h"
#include "core/units.h"
#include "u3m/image_io.h"

namespace u3mscan::synthetic {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

constexpr int kTruthVersion = 1;

struct MapEntry {
  const char* key;   // name in truth.json "maps" and file stem
  const char* unit;  // for truth.json "units"
  Image SceneTruth::*image;
  int channels;
};

// Every map of SceneTruth, in the order they are written.
const std::vector<MapEntry>& Maps() {
  static const std::vector<MapEntry> maps = {
      {"height_mm", "mm, +z toward the camera", &SceneTruth::height_mm, 1},
      {"normal", "unit vector, world frame x right, y up, z out of the fabric", &SceneTruth::normal, 3},
      {"base_color", "linear RGB, 0..1", &SceneTruth::base_color, 3},
      {"roughness", "0..1", &SceneTruth::roughness, 1},
      {"specular", "0..1", &SceneTruth::specular, 1},
      {"specular_tint", "0..1", &SceneTruth::specular_tint, 1},
      {"sheen", "0..1", &SceneTruth::sheen, 1},
      {"sheen_tint", "0..1", &SceneTruth::sheen_tint, 1},
      {"metallic", "0..1", &SceneTruth::metallic, 1},
      {"anisotropic", "0..1", &SceneTruth::anisotropic, 1},
      {"alpha", "0 hole, 1 fabric", &SceneTruth::alpha, 1},
      {"tangent", "unit vector, world frame, fibre direction orthogonal to normal", &SceneTruth::tangent, 3},
  };
  return maps;
}

json YarnJson(const YarnTruth& y) {
  return json{{"name", y.name},
              {"base_color", {y.base_color[0], y.base_color[1], y.base_color[2]}},
              {"roughness", y.roughness},
              {"specular", y.specular},
              {"specular_tint", y.specular_tint},
              {"sheen", y.sheen},
              {"sheen_tint", y.sheen_tint},
              {"metallic", y.metallic},
              {"anisotropic", y.anisotropic},
              {"width_mm", y.width_mm},
              {"thickness_mm", y.thickness_mm},
              {"spacing_mm", y.spacing_mm}};
}

// Mean of each parameter over the fabric (alpha-weighted: holes carry no material).
json Means(const SceneTruth& t) {
  const auto alpha = t.alpha.plane(0);
  double weight = 0.0;
  for (float a : alpha) weight += a;
  auto mean = [&](const Image& image, int channel) {
    if (weight <= 0.0) return 0.0;
    const auto plane = image.plane(channel);
    double sum = 0.0;
    for (std::size_t i = 0; i < plane.size(); ++i) sum += static_cast<double>(plane[i]) * alpha[i];
    return sum / weight;
  };
  return json{{"base_color", {mean(t.base_color, 0), mean(t.base_color, 1), mean(t.base_color, 2)}},
              {"roughness", mean(t.roughness, 0)},
              {"specular", mean(t.specular, 0)},
              {"specular_tint", mean(t.specular_tint, 0)},
              {"sheen", mean(t.sheen, 0)},
              {"sheen_tint", mean(t.sheen_tint, 0)},
              {"metallic", mean(t.metallic, 0)},
              {"anisotropic", mean(t.anisotropic, 0)},
              {"height_mm", mean(t.height_mm, 0)},
              {"alpha", t.alpha.ChannelMean(0)}};
}

json TruthJson(const SceneTruth& t) {
  json maps = json::object(), units = json::object();
  for (const MapEntry& m : Maps()) {
    maps[m.key] = std::string(m.key) + ".exr";
    units[m.key] = m.unit;
  }
  json yarns = json::array();
  for (const YarnTruth& y : t.yarns) yarns.push_back(YarnJson(y));
  return json{{"format", "u3mscan-truth"},
              {"version", kTruthVersion},
              {"scene", t.name},
              {"description", t.description},
              {"seed", t.seed},
              {"reflectance_model", ReflectanceModelName(t.model)},
              {"grid",
               {{"width", t.height_mm.width()},
                {"height", t.height_mm.height()},
                {"pitch_mm", t.pitch_mm},
                {"dpi", t.pitch_mm > 0 ? PitchMmToDpi(t.pitch_mm) : 0.0},
                {"pixel_to_world", "x_mm = col * pitch_mm, y_mm = -row * pitch_mm (x right, y up)"}}},
              {"height_range_mm", {t.height_min_mm, t.height_max_mm}},
              {"repeat_mm", {t.repeat_x_mm, t.repeat_y_mm}},
              {"maps", maps},
              {"units", units},
              {"means", Means(t)},
              {"yarns", yarns}};
}

fs::path UniqueSibling(const fs::path& dir, const char* tag) {
  static std::atomic<unsigned> counter{0};
  const auto ticks = std::chrono::steady_clock::now().time_since_epoch().count();
  // Built with append: GCC 12 warns falsely (-Wrestrict) on a chain of operator+ starting at a literal.
  std::string name(".");
  name.append(dir.filename().string()).append(".").append(tag).append("-");
  name.append(std::to_string(ticks)).append("-").append(std::to_string(counter.fetch_add(1)));
  return dir.parent_path() / name;
}

template <typename T>
T Get(const json& j, const std::string& file, const std::string& pointer) {
  try {
    return j.at(json::json_pointer(pointer)).get<T>();
  } catch (const json::exception&) {
    throw InputError(file, pointer, "a value of the expected type");
  }
}

}  // namespace

void WriteTruth(const SceneTruth& truth, const json& extra, const fs::path& dir) {
  if (!extra.is_null() && !extra.is_object()) throw std::invalid_argument("WriteTruth: extra must be a JSON object");
  json doc = TruthJson(truth);
  if (extra.is_object()) {
    for (const auto& [key, value] : extra.items()) {
      if (doc.contains(key)) throw std::invalid_argument("WriteTruth: extra member '" + key + "' is reserved");
      doc[key] = value;
    }
  }
  const fs::path target = dir.has_filename() ? dir : dir.parent_path();
  std::error_code ec;
  if (!target.parent_path().empty()) fs::create_directories(target.parent_path(), ec);
  const fs::path temp = UniqueSibling(target, "partial");
  fs::create_directories(temp, ec);
  if (ec) throw InputError(temp.string(), "", "a writable directory: " + ec.message());
  try {
    ImageWriteOptions options;
    options.format = SampleFormat::kFloat32;
    options.encoding = PixelEncoding::kLinear;
    for (const MapEntry& m : Maps()) WriteImageFile(truth.*(m.image), temp / (std::string(m.key) + ".exr"), options);
    const fs::path json_path = temp / "truth.json";
    std::ofstream out(json_path);
    out << doc.dump(2) << "\n";
    out.close();
    if (!out) throw InputError((target / "truth.json").string(), "", "a writable file");
    // Replace an older truth: move it aside, move the new one in, then delete the old one.
    fs::path old;
    if (fs::exists(target)) {
      old = UniqueSibling(target, "old");
      fs::rename(target, old);
    }
    fs::rename(temp, target);
    if (!old.empty()) fs::remove_all(old, ec);
  } catch (const fs::filesystem_error& e) {
    fs::remove_all(temp, ec);
    throw InputError(target.string(), "", std::string("a directory that can be written and renamed: ") + e.what());
  } catch (...) {
    fs::remove_all(temp, ec);
    throw;
  }
}

SceneTruth ReadTruth(const fs::path& dir, json* json_out) {
  const fs::path json_path = dir / "truth.json";
  const std::string file = json_path.string();
  std::ifstream in(json_path);
  if (!in) throw InputError(file, "", "a readable truth.json");
  json doc;
  try {
    doc = json::parse(in);
  } catch (const json::exception& e) {
    throw InputError(file, "", std::string("valid JSON: ") + e.what());
  }
  if (Get<std::string>(doc, file, "/format") != "u3mscan-truth") {
    throw InputError(file, "/format", "\"u3mscan-truth\"");
  }
  if (Get<int>(doc, file, "/version") != kTruthVersion) {
    throw InputError(file, "/version", std::to_string(kTruthVersion));
  }
  SceneTruth t;
  t.name = Get<std::string>(doc, file, "/scene");
  t.description = Get<std::string>(doc, file, "/description");
  t.seed = Get<std::uint64_t>(doc, file, "/seed");
  t.pitch_mm = Get<double>(doc, file, "/grid/pitch_mm");
  const int width = Get<int>(doc, file, "/grid/width"), height = Get<int>(doc, file, "/grid/height");
  if (!ParseReflectanceModel(Get<std::string>(doc, file, "/reflectance_model"), &t.model)) {
    throw InputError(file, "/reflectance_model", ReflectanceModelChoices());
  }
  t.height_min_mm = Get<double>(doc, file, "/height_range_mm/0");
  t.height_max_mm = Get<double>(doc, file, "/height_range_mm/1");
  t.repeat_x_mm = Get<double>(doc, file, "/repeat_mm/0");
  t.repeat_y_mm = Get<double>(doc, file, "/repeat_mm/1");
  const json& yarns = doc.contains("yarns") ? doc["yarns"] : json::array();
  for (std::size_t i = 0; i < yarns.size(); ++i) {
    const std::string p = "/yarns/" + std::to_string(i);
    YarnTruth y;
    y.name = Get<std::string>(doc, file, p + "/name");
    for (int c = 0; c < 3; ++c) y.base_color[c] = Get<float>(doc, file, p + "/base_color/" + std::to_string(c));
    y.roughness = Get<float>(doc, file, p + "/roughness");
    y.specular = Get<float>(doc, file, p + "/specular");
    y.specular_tint = Get<float>(doc, file, p + "/specular_tint");
    y.sheen = Get<float>(doc, file, p + "/sheen");
    y.sheen_tint = Get<float>(doc, file, p + "/sheen_tint");
    y.metallic = Get<float>(doc, file, p + "/metallic");
    y.anisotropic = Get<float>(doc, file, p + "/anisotropic");
    y.width_mm = Get<double>(doc, file, p + "/width_mm");
    y.thickness_mm = Get<double>(doc, file, p + "/thickness_mm");
    y.spacing_mm = Get<double>(doc, file, p + "/spacing_mm");
    t.yarns.push_back(std::move(y));
  }
  for (const MapEntry& m : Maps()) {
    const std::string pointer = std::string("/maps/") + m.key;
    const fs::path path = dir / Get<std::string>(doc, file, pointer);
    Image image = ReadImageFile(path, PixelEncoding::kLinear);
    if (image.width() != width || image.height() != height || image.channels() != m.channels) {
      throw InputError(path.string(), "", std::to_string(width) + "x" + std::to_string(height) + "x" +
                                              std::to_string(m.channels) + " as truth.json /grid says");
    }
    image.set_pitch_mm(t.pitch_mm);
    t.*(m.image) = std::move(image);
  }
  if (json_out) *json_out = std::move(doc);
  return t;
}

}  // namespace u3mscan::synthetic
