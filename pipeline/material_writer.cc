#include "pipeline/material_writer.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <system_error>

#include "core/colour.h"
#include "core/error.h"
#include "core/units.h"
#include "u3m/json_value.h"
#include "u3m/texture_map.h"

namespace u3mscan {
namespace fs = std::filesystem;

namespace {

// Texture file formats: colour 8-bit sRGB PNG (what every viewer shows right), data maps 16-bit
// PNG (roughness steps of 1/255 are visible in highlights; heights need the range).
constexpr SampleFormat kColourFormat = SampleFormat::kUInt8;
constexpr SampleFormat kDataFormat = SampleFormat::kUInt16;

TextureImage TextureImageFor(const Image& map, const std::string& path) { return TextureImageOf(path, GeometryOf(map)); }

double PlaneStdDev(const Image& image, int channel, double* mean_out) {
  const double mean = image.ChannelMean(channel);
  double sum2 = 0.0;
  for (float v : image.plane(channel)) sum2 += (v - mean) * (v - mean);
  if (mean_out) *mean_out = mean;
  return image.pixel_count() ? std::sqrt(sum2 / static_cast<double>(image.pixel_count())) : 0.0;
}

bool BaseColourIsUniform(const Image& base_color, double threshold, Rgb3* mean) {
  double m[3];
  bool uniform = true;
  for (int c = 0; c < 3; ++c) uniform = PlaneStdDev(base_color, c, &m[c]) <= threshold && uniform;
  *mean = {m[0], m[1], m[2]};
  return uniform;
}

bool NormalIsUniform(const Image& normal, double max_angle_deg, Vec3* mean) {
  double m[3] = {normal.ChannelMean(0), normal.ChannelMean(1), normal.ChannelMean(2)};
  const double length = std::sqrt(m[0] * m[0] + m[1] * m[1] + m[2] * m[2]);
  if (length > 0.0) {
    for (double& v : m) v /= length;
  } else {
    m[0] = m[1] = 0.0;
    m[2] = 1.0;
  }
  *mean = {m[0], m[1], m[2]};
  const double min_cos = std::cos(DegToRad(max_angle_deg));
  const auto x = normal.plane(0), y = normal.plane(1), z = normal.plane(2);
  for (std::size_t i = 0; i < x.size(); ++i) {
    if (x[i] * m[0] + y[i] * m[1] + z[i] * m[2] < min_cos) return false;
  }
  return true;
}

std::string TexturePath(const std::string& side, const std::string& key) { return "textures/" + side + "_" + key + ".png"; }

struct SideBuild {
  Visualization visualization;
  std::vector<ParameterRecord> records;
};

SideBuild BuildSide(const SideMaps& maps, const fs::path& staging, const UniformityThresholds& thresholds,
                    ScanMaterialResult* result) {
  SideBuild build;
  Visualization& v = build.visualization;
  auto record = [&](const std::string& key, ParameterSource source, double value, const std::string& reason,
                    const std::string& unreliable_reason = "") {
    build.records.push_back({maps.side + "/" + key, source, reason, value, 0.0, unreliable_reason});
  };

  // Base colour: sRGB texture unless uniform.
  Rgb3 mean_colour;
  if (BaseColourIsUniform(maps.base_color, thresholds.base_color_std, &mean_colour)) {
    v.basecolor = ColorParam{true, mean_colour, std::nullopt};
    record("basecolor", ParameterSource::kConstant, PrincipledLuminance({mean_colour.r, mean_colour.g, mean_colour.b}),
           "uniform within noise");
  } else {
    const std::string path = TexturePath(maps.side, "basecolor");
    WriteTextureMap(maps.base_color, MapKind::kColour, staging / path, kColourFormat);
    v.basecolor = ColorParam{true, mean_colour, ColorTexture{BlendMode::kMultiply, Rgb3{1, 1, 1}, TextureImageFor(maps.base_color, path)}};
    result->files.push_back(path);
    record("basecolor", ParameterSource::kMeasured, PrincipledLuminance({mean_colour.r, mean_colour.g, mean_colour.b}),
           "photometric stereo albedo, refined by the fit");
  }

  // Normal: tangent space with tangent = +x and bitangent = +y of the finished map, so for a flat
  // sample the tangent-space normal is the world normal; OpenGL convention (+y = green = up).
  Vec3 mean_normal;
  if (NormalIsUniform(maps.normal, thresholds.normal_angle_deg, &mean_normal)) {
    v.normal = NormalParam{true, mean_normal, std::nullopt};
    record("normal", ParameterSource::kConstant, mean_normal.z, "flat within " + std::to_string(thresholds.normal_angle_deg) + " deg");
  } else {
    const std::string path = TexturePath(maps.side, "normal");
    WriteTextureMap(maps.normal, MapKind::kNormal, staging / path, kDataFormat);
    v.normal = NormalParam{true, mean_normal, NormalTexture{1.0, TextureImageFor(maps.normal, path)}};
    result->files.push_back(path);
    record("normal", ParameterSource::kMeasured, mean_normal.z, maps.normal_source);
  }

  // Displacement: 0..1 over the height range; the mm scale goes into our custom section.
  float lo = INFINITY, hi = -INFINITY;
  for (float h : maps.height_mm.plane(0)) {
    lo = std::min(lo, h);
    hi = std::max(hi, h);
  }
  if (!(hi - lo > thresholds.height_range_mm)) {
    v.displacement = ScalarParam{true, 0.0, std::nullopt};
    record("displacement", ParameterSource::kConstant, 0.0, "flat: height range below " +
                                                             std::to_string(thresholds.height_range_mm * 1000) + " um");
  } else {
    Image unit(maps.height_mm.width(), maps.height_mm.height(), 1, 0.0f, maps.height_mm.pitch_mm());
    const auto in = maps.height_mm.plane(0);
    auto out = unit.plane(0);
    for (std::size_t i = 0; i < in.size(); ++i) out[i] = (in[i] - lo) / (hi - lo);
    const std::string path = TexturePath(maps.side, "displacement");
    WriteTextureMap(unit, MapKind::kData, staging / path, kDataFormat);
    v.displacement = ScalarParam{true, 0.5, ScalarTexture{1.0, 0.0, TextureImageFor(unit, path)}};
    result->files.push_back(path);
    result->displacement_mm_per_unit = hi - lo;
    result->displacement_zero_mm = lo;
    record("displacement", ParameterSource::kMeasured, hi - lo,
           "integrated normals; value 1 = " + std::to_string(hi - lo) + " mm above value 0", maps.height_unreliable_reason);
  }

  // Alpha from the backlight frame, only where the sample has holes.
  if (!maps.alpha.empty()) {
    const std::string path = TexturePath(maps.side, "alpha");
    WriteTextureMap(maps.alpha, MapKind::kData, staging / path, kColourFormat);
    v.alpha = ScalarParam{true, maps.alpha.ChannelMean(0), ScalarTexture{1.0, 0.0, TextureImageFor(maps.alpha, path)}};
    result->files.push_back(path);
    record("alpha", ParameterSource::kMeasured, maps.alpha.ChannelMean(0), "backlight frame");
  } else {
    record("alpha", ParameterSource::kNotApplicable, 1.0, "no holes seen (or no backlight frame)");
  }

  for (const ScalarMapChoice& choice : maps.scalars) {
    ScalarParam* param = nullptr;
    for (const ScalarKey& key : ScalarKeys()) {
      if (key.name == choice.u3m_key) param = &(v.*(key.member));
    }
    if (!param) throw std::logic_error("unknown U3M scalar key " + choice.u3m_key);
    if (choice.source == ParameterSource::kMeasured && !choice.map.empty()) {
      const std::string path = TexturePath(maps.side, choice.u3m_key);
      WriteTextureMap(choice.map, MapKind::kData, staging / path, kDataFormat);
      *param = ScalarParam{true, choice.value, ScalarTexture{choice.texture_factor, 0.0, TextureImageFor(choice.map, path)}};
      result->files.push_back(path);
    } else {
      *param = ScalarParam{true, choice.value, std::nullopt};
    }
    record(choice.u3m_key, choice.source, choice.value, choice.reason, choice.unreliable_reason);
  }
  return build;
}

fs::path MakeStagingDir(const fs::path& out_dir) {
  std::random_device device;
  for (int attempt = 0; attempt < 16; ++attempt) {
    const fs::path dir = out_dir / (".u3mscan-staging-" + std::to_string(device()));
    std::error_code ec;
    if (fs::create_directory(dir, ec)) return dir;
  }
  throw InputError(out_dir.string(), "", "a writable output folder");
}

}  // namespace

Image RenderPreview(const SideMaps& side) {
  const Image& colour = side.base_color;
  Image preview(colour.width(), colour.height(), 3, 0.0f, colour.pitch_mm());
  // Light from the upper left, 45 deg up; ambient keeps shadowed threads visible.
  const double l[3] = {-0.5, 0.5, 0.7071};
  constexpr double kAmbient = 0.25;
  for (std::size_t i = 0; i < colour.pixel_count(); ++i) {
    double n_dot_l = l[2];
    if (!side.normal.empty()) {
      n_dot_l = side.normal.plane(0)[i] * l[0] + side.normal.plane(1)[i] * l[1] + side.normal.plane(2)[i] * l[2];
    }
    const double shade = kAmbient + (1.0 - kAmbient) * std::max(0.0, n_dot_l) / l[2];
    for (int c = 0; c < 3; ++c) preview.plane(c)[i] = static_cast<float>(std::min(1.0, colour.plane(c)[i] * shade));
  }
  return preview;
}

ScanMaterialResult WriteScanMaterial(const ScanMaterialRequest& request, const fs::path& out_dir, bool overwrite,
                                      const UniformityThresholds& thresholds) {
  if (request.sides.empty()) throw std::invalid_argument("WriteScanMaterial: no side to write");
  std::error_code ec;
  fs::create_directories(out_dir, ec);
  if (ec) throw InputError(out_dir.string(), "", "a folder that can be created: " + ec.message());

  ScanMaterialResult result;
  const fs::path staging = MakeStagingDir(out_dir);
  try {
    fs::create_directories(staging / "textures");
    Material material;
    material.id = request.id.value_or(NewUuid4());
    material.name = request.name;
    material.description = request.description;
    material.created_ms = request.created_ms.value_or(NowUtcMs());
    material.modified_ms = material.created_ms;

    for (const SideMaps& side : request.sides) {
      SideBuild build = BuildSide(side, staging, thresholds, &result);
      result.parameters.insert(result.parameters.end(), build.records.begin(), build.records.end());
      if (side.side == "front") material.front = std::move(build.visualization);
      else if (side.side == "back") material.back = std::move(build.visualization);
      else throw std::invalid_argument("WriteScanMaterial: side must be front or back, got " + side.side);
    }
    if (request.thickness_mm && request.weight_gsm) {
      Physics physics;
      physics.thickness_mm = request.thickness_mm;
      physics.weight_g_per_m2 = request.weight_gsm;
      material.physics = physics;
    }

    nlohmann::json custom = request.custom_section;
    if (result.displacement_mm_per_unit > 0.0) {
      custom["displacement"] = {{"mm_per_unit", result.displacement_mm_per_unit},
                                {"zero_mm", result.displacement_zero_mm},
                                {"meaning", "height_mm = zero_mm + value * mm_per_unit, +z toward a camera above"}};
    }
    // A flagged parameter the caller's custom section does not list (the displacement) is listed
    // there with its flag, so the material itself says what not to trust.
    if (custom.contains("parameter_sources") && custom["parameter_sources"].is_object()) {
      for (const ParameterRecord& p : result.parameters) {
        if (p.reliable() || custom["parameter_sources"].contains(p.name)) continue;
        custom["parameter_sources"][p.name] = {{"source", ParameterSourceName(p.source)}, {"reason", p.reason},
                                               {"reliable", false}, {"unreliable_reason", p.unreliable_reason}};
      }
    }
    JsonValue sections = JsonValue::Object();
    sections.Set(request.vendor_key, ParseJson(custom.dump(), "custom section"));
    material.custom = sections;

    // The lowest version that holds the content decides whether a preview (1.1 only) goes in.
    const std::string out_name = request.file_stem + (request.package ? ".u3ma" : ".u3m");
    SchemaVersion version;
    if (request.schema == "auto") version = LowestVersionFor(material, out_name);
    else if (request.schema == "1.0") version = SchemaVersion::k1_0;
    else if (request.schema == "1.1") version = SchemaVersion::k1_1;
    else throw InputError("--schema", "", "auto, 1.0 or 1.1; got \"" + request.schema + "\"");
    if (version == SchemaVersion::k1_1) {
      for (const SideMaps& side : request.sides) {
        const Image preview = RenderPreview(side);
        const std::string path = "textures/" + side.side + "_preview.png";
        WriteTextureMap(preview, MapKind::kColour, staging / path, kColourFormat);
        const MapGeometry geometry = GeometryOf(preview);
        Visualization* v = side.side == "front" ? &*material.front : &*material.back;
        v->preview = PreviewImage{path, geometry.width_mm, geometry.height_mm, geometry.dpi_x, geometry.dpi_y};
        result.files.push_back(path);
      }
    }

    SaveOptions save;
    save.version = version;
    save.overwrite = overwrite;
    save.update_modified = false;  // created == modified: a rerun gives the same material
    result.material_path = out_dir / out_name;
    const SaveResult saved = SaveMaterial(material, staging, result.material_path, save);
    result.version = saved.version;
  } catch (...) {
    fs::remove_all(staging, ec);
    throw;
  }
  fs::remove_all(staging, ec);
  return result;
}

}  // namespace u3mscan
