#include "u3m/example_material.h"

#include <cmath>
#include <system_error>

#include "core/error.h"
#include "core/units.h"
#include "u3m/texture_map.h"
#include "u3mscan/version.h"

namespace u3mscan {
namespace {

namespace fs = std::filesystem;

constexpr int kThreadPx = 16;                 // one thread crossing per 16 px
constexpr double kReliefMm = 0.3;             // displacement 1.0 = 0.3 mm above displacement 0.0
constexpr double kThicknessMm = 0.45;
constexpr double kWeightGPerM2 = 180.0;
constexpr const char* kExampleSource = "built-in example (u3mscan example)";

// Relief of a plain weave in 0..1: in each cell either the warp (running along y) or the weft
// (along x) is on top, with a rounded thread profile across it. Periodic over 2 cells.
double WeaveHeight(int row, int col) {
  const int cell_x = col / kThreadPx, cell_y = row / kThreadPx;
  const double u = (col % kThreadPx + 0.5) / kThreadPx;  // 0..1 across the cell
  const double v = (row % kThreadPx + 0.5) / kThreadPx;
  const bool warp_on_top = (cell_x + cell_y) % 2 == 0;
  const double across = warp_on_top ? u : v;              // profile across the upper thread
  const double along = warp_on_top ? v : u;               // dips where it goes under the crossing thread
  const double profile = std::sin(kPi * across);          // round thread
  const double dip = 0.75 + 0.25 * std::sin(kPi * along);
  return 0.15 + 0.85 * profile * dip;
}

struct ExampleMaps {
  Image basecolor, normal, roughness, displacement, preview;
};

ExampleMaps MakeMaps(int size, double pitch_mm) {
  ExampleMaps maps;
  Image height(size, size, 1, 0.0f, pitch_mm);
  for (int r = 0; r < size; ++r)
    for (int c = 0; c < size; ++c) height.at(0, r, c) = static_cast<float>(WeaveHeight(r, c));
  maps.displacement = height;

  // Linear colours: a madder red whose yarn darkens toward the shaded valleys.
  maps.basecolor = Image(size, size, 3, 0.0f, pitch_mm);
  maps.roughness = Image(size, size, 1, 0.0f, pitch_mm);
  maps.normal = Image(size, size, 3, 0.0f, pitch_mm);
  const double rgb[3] = {0.42, 0.09, 0.07};
  for (int r = 0; r < size; ++r) {
    for (int c = 0; c < size; ++c) {
      const double h = height.at(0, r, c);
      for (int k = 0; k < 3; ++k) maps.basecolor.at(k, r, c) = static_cast<float>(rgb[k] * (0.55 + 0.45 * h));
      maps.roughness.at(0, r, c) = static_cast<float>(0.85 - 0.25 * h);  // thread tops a bit smoother
      // Tangent-space normal from the relief in mm; +Y is up in the image (OpenGL), rows grow down.
      const int left = (c + size - 1) % size, right = (c + 1) % size;
      const int up = (r + size - 1) % size, down = (r + 1) % size;
      const double dh_dx = (height.at(0, r, right) - height.at(0, r, left)) * kReliefMm / (2.0 * pitch_mm);
      const double dh_dy_up = (height.at(0, up, c) - height.at(0, down, c)) * kReliefMm / (2.0 * pitch_mm);
      const double len = std::sqrt(dh_dx * dh_dx + dh_dy_up * dh_dy_up + 1.0);
      maps.normal.at(0, r, c) = static_cast<float>(-dh_dx / len);
      maps.normal.at(1, r, c) = static_cast<float>(-dh_dy_up / len);
      maps.normal.at(2, r, c) = static_cast<float>(1.0 / len);
    }
  }
  // Preview: the colour map at half resolution (2x2 box filter).
  const int half = size / 2;
  maps.preview = Image(half, half, 3, 0.0f, 2.0 * pitch_mm);
  for (int k = 0; k < 3; ++k)
    for (int r = 0; r < half; ++r)
      for (int c = 0; c < half; ++c)
        maps.preview.at(k, r, c) = 0.25f * (maps.basecolor.at(k, 2 * r, 2 * c) + maps.basecolor.at(k, 2 * r + 1, 2 * c) +
                                            maps.basecolor.at(k, 2 * r, 2 * c + 1) + maps.basecolor.at(k, 2 * r + 1, 2 * c + 1));
  return maps;
}

JsonValue OwnSection(const ExampleOptions& options) {
  JsonValue section = JsonValue::Object();
  section.Set("software", JsonValue::String(kSoftwareName));
  section.Set("software_version", JsonValue::String(kSoftwareVersion));
  section.Set("source", JsonValue::String(kExampleSource));
  JsonValue displacement = JsonValue::Object();
  displacement.Set("unit", JsonValue::String("mm"));
  displacement.Set("mm_per_unit", JsonValue::Number(kReliefMm));
  displacement.Set("note", JsonValue::String("height above the lowest point = value * mm_per_unit"));
  section.Set("displacement", std::move(displacement));
  section.Set("pixel_pitch_mm", JsonValue::Number(options.pitch_mm));
  return section;
}

// An earlier run of the example may be replaced without asking (the main job runs it again and
// again); anything else at `out` is the user's and needs `overwrite`.
bool IsPreviousExample(const fs::path& out) {
  std::error_code ec;
  if (!fs::exists(out, ec)) return false;
  try {
    const LoadedMaterial loaded = LoadMaterial(out);
    const JsonValue* own = loaded.material.custom.Find(kOwnVendorKey);
    const JsonValue* source = own ? own->Find("source") : nullptr;
    return source && source->is_string() && source->text() == kExampleSource;
  } catch (const InputError&) {
    return false;
  }
}

}  // namespace

bool ExampleOptions::Check(std::string* why) const {
  const auto fail = [&](const char* reason) {
    if (why) *why = reason;
    return false;
  };
  if (size_px < 2 * kThreadPx || size_px > 4096 || size_px % (2 * kThreadPx) != 0)
    return fail("size_px must be a multiple of 32 between 32 and 4096 (whole weave repeats tile seamlessly)");
  if (!(pitch_mm > 0.001 && pitch_mm < 10.0)) return fail("pitch_mm must be between 0.001 and 10 mm");
  if (name.empty()) return fail("name must not be empty");
  return true;
}

SaveResult WriteExampleMaterial(const fs::path& out, const ExampleOptions& options) {
  std::string why;
  if (!options.Check(&why)) throw InputError(out.string(), "example options", why);
  const ExampleMaps maps = MakeMaps(options.size_px, options.pitch_mm);

  // Textures go to a private staging folder; SaveMaterial copies them beside the output atomically.
  const fs::path staging = fs::temp_directory_path() / ("u3mscan-example-" + NewUuid4().substr(0, 8));
  fs::create_directories(staging / "textures");
  struct Cleanup {
    fs::path dir;
    ~Cleanup() {
      std::error_code ignored;
      fs::remove_all(dir, ignored);
    }
  } cleanup{staging};

  const MapGeometry g_color = WriteTextureMap(maps.basecolor, MapKind::kColour, staging / "textures/basecolor.png", SampleFormat::kUInt8);
  const MapGeometry g_normal = WriteTextureMap(maps.normal, MapKind::kNormal, staging / "textures/normal.png", SampleFormat::kUInt16);
  const MapGeometry g_rough = WriteTextureMap(maps.roughness, MapKind::kData, staging / "textures/roughness.png", SampleFormat::kUInt8);
  const MapGeometry g_disp = WriteTextureMap(maps.displacement, MapKind::kData, staging / "textures/displacement.png", SampleFormat::kUInt16);

  Visualization front;
  // Constants are the means of the values a reader gets back from the files (quantisation included).
  const auto colour_mean = ColourMapMean(maps.basecolor, SampleFormat::kUInt8);
  front.basecolor.constant = Rgb3{colour_mean[0], colour_mean[1], colour_mean[2]};
  front.basecolor.texture = ColorTexture{BlendMode::kMultiply, Rgb3{1.0, 1.0, 1.0}, TextureImageOf("textures/basecolor.png", g_color)};
  const auto normal_mean = NormalMapMean(maps.normal, SampleFormat::kUInt16);
  front.normal.constant = Vec3{normal_mean[0], normal_mean[1], normal_mean[2]};
  front.normal.texture = NormalTexture{1.0, TextureImageOf("textures/normal.png", g_normal)};
  front.roughness.constant = ScalarMapMean(maps.roughness, SampleFormat::kUInt8);
  front.roughness.texture = ScalarTexture{1.0, 0.0, TextureImageOf("textures/roughness.png", g_rough)};
  front.displacement.constant = ScalarMapMean(maps.displacement, SampleFormat::kUInt16);
  front.displacement.texture = ScalarTexture{1.0, 0.0, TextureImageOf("textures/displacement.png", g_disp)};
  front.sheen_value.constant = 0.3;  // fabrics scatter at grazing angles
  front.sheen_tint.constant = 0.5;

  Material m;
  m.id = NewUuid4();
  m.name = options.name;
  m.description = "Procedural plain weave written by u3mscan from built-in values";
  m.created_ms = m.modified_ms = NowUtcMs();
  m.custom = JsonValue::Object();
  m.custom.Set(std::string(kOwnVendorKey), OwnSection(options));

  const bool full = !options.version || *options.version == SchemaVersion::k1_1;
  if (full) {  // 1.1 content: a preview and physics
    const MapGeometry g_preview = WriteTextureMap(maps.preview, MapKind::kColour, staging / "preview.png", SampleFormat::kUInt8);
    front.preview = PreviewImage{"preview.png", g_preview.width_mm, g_preview.height_mm, g_preview.dpi_x, g_preview.dpi_y};
    Physics physics;
    physics.thickness_mm = kThicknessMm;
    physics.weight_g_per_m2 = kWeightGPerM2;
    physics.composition = std::vector<CompositionPart>{{1.0, "Cotton", std::nullopt}};
    physics.material_type = NamedType{"Woven", std::nullopt};
    physics.construction = NamedType{"Plain weave", std::nullopt};
    m.physics = physics;
  }
  m.front = front;

  SaveOptions save;
  save.version = options.version;
  save.overwrite = options.overwrite || IsPreviousExample(out);
  return SaveMaterial(m, staging, out, save);
}

}  // namespace u3mscan
