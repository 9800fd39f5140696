// Scene presets and the sampler that turns a SurfaceModel into truth maps on a metric grid.
// Parameters per preset are chosen from published fabric constructions (ends/picks per cm, yarn
// diameters) and typical Principled values for textiles; docs/synthetic-scenes.md lists them.

#include "datasets_synthetic/scene.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <map>
#include <numbers>
#include <stdexcept>

#include "core/parallel.h"
#include "datasets_synthetic/scene_internal.h"

namespace u3mscan::synthetic {

namespace internal {

void ApplyYarn(const YarnMaterial& yarn, float thread_u0, float thread_u1, float fibre_noise, SurfacePoint* p) {
  // Thread-to-thread brightness change plus a small hue shift (red vs blue) from a second number.
  const float brightness = 1.0f + yarn.thread_color_variation * (2.0f * thread_u0 - 1.0f) +
                           yarn.fibre_color_variation * fibre_noise;
  const float hue = 0.3f * yarn.thread_color_variation * (2.0f * thread_u1 - 1.0f);
  for (int c = 0; c < 3; ++c) {
    const float shift = 1.0f + hue * static_cast<float>(c - 1);
    p->base_color[c] = std::clamp(yarn.base_color[c] * brightness * shift, 0.0f, 1.0f);
  }
  p->roughness = std::clamp(yarn.roughness + yarn.thread_roughness_variation * (2.0f * thread_u1 - 1.0f), 0.0f, 1.0f);
  p->specular = yarn.specular;
  p->specular_tint = yarn.specular_tint;
  p->sheen = yarn.sheen;
  p->sheen_tint = yarn.sheen_tint;
  p->metallic = 0.0f;  // fabric is a dielectric
  p->anisotropic = yarn.anisotropic;
  p->alpha = 1.0f;
}

YarnTruth ToYarnTruth(const std::string& name, const YarnMaterial& yarn, double width_mm, double thickness_mm,
                      double spacing_mm) {
  YarnTruth t;
  t.name = name;
  t.base_color = {yarn.base_color[0], yarn.base_color[1], yarn.base_color[2]};
  t.roughness = yarn.roughness;
  t.specular = yarn.specular;
  t.specular_tint = yarn.specular_tint;
  t.sheen = yarn.sheen;
  t.sheen_tint = yarn.sheen_tint;
  t.metallic = 0.0f;
  t.anisotropic = yarn.anisotropic;
  t.width_mm = width_mm;
  t.thickness_mm = thickness_mm;
  t.spacing_mm = spacing_mm;
  return t;
}

namespace {

YarnMaterial Yarn(float r, float g, float b, float roughness, float specular, float sheen, float sheen_tint,
                  float anisotropic, float thread_variation, float fibre_variation) {
  YarnMaterial m;
  m.base_color[0] = r;
  m.base_color[1] = g;
  m.base_color[2] = b;
  m.roughness = roughness;
  m.specular = specular;
  m.sheen = sheen;
  m.sheen_tint = sheen_tint;
  m.anisotropic = anisotropic;
  m.thread_color_variation = thread_variation;
  m.fibre_color_variation = fibre_variation;
  m.thread_roughness_variation = 0.5f * thread_variation;
  return m;
}

// One constant material without variation: the extreme and analytic presets.
YarnMaterial Uniform(float grey, float roughness, float specular) {
  return Yarn(grey, grey, grey, roughness, specular, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f);
}

// Cotton poplin: 2 x 2 plain weave, ~33 ends/cm and ~31 picks/cm, two shades of a dyed yarn so
// the structure shows in colour as well as in relief.
WeaveSpec PlainSpec() {
  WeaveSpec s = PlainPattern();
  s.warp_spacing_mm = 0.30;
  s.weft_spacing_mm = 0.32;
  s.warp_width_mm = 0.30;  // warps touch: no gaps, no holes
  s.weft_width_mm = 0.30;
  s.warp_thickness_mm = 0.10;
  s.weft_thickness_mm = 0.10;
  s.crimp_mm = 0.05;
  s.slub = 0.08;
  s.slub_length_mm = 4.0;
  s.ply_depth_mm = 0.012;
  s.ply_pitch_mm = 0.4;
  s.warp = Yarn(0.60f, 0.18f, 0.10f, 0.75f, 0.5f, 0.1f, 0.5f, 0.1f, 0.06f, 0.08f);
  s.weft = Yarn(0.45f, 0.11f, 0.08f, 0.78f, 0.5f, 0.1f, 0.5f, 0.1f, 0.06f, 0.08f);
  return s;
}

// Gabardine/chino: 2/1 twill, fine dense warp (40 ends/cm) over a coarser weft.
WeaveSpec TwillSpec() {
  WeaveSpec s = TwillPattern(2, 1);
  s.warp_spacing_mm = 0.25;
  s.weft_spacing_mm = 0.35;
  s.warp_width_mm = 0.25;
  s.weft_width_mm = 0.33;
  s.warp_thickness_mm = 0.12;
  s.weft_thickness_mm = 0.10;
  s.crimp_mm = 0.05;
  s.slub = 0.06;
  s.ply_depth_mm = 0.015;
  s.ply_pitch_mm = 0.45;
  s.warp = Yarn(0.45f, 0.36f, 0.22f, 0.70f, 0.5f, 0.15f, 0.4f, 0.2f, 0.05f, 0.06f);
  s.weft = Yarn(0.40f, 0.32f, 0.20f, 0.72f, 0.5f, 0.15f, 0.4f, 0.2f, 0.05f, 0.06f);
  return s;
}

// Silk/filament satin: 5-harness warp-faced satin, dense fine warp floating over four picks. Low
// roughness and strong anisotropy along the floats; no ply grooves (filament yarn).
WeaveSpec SatinSpec() {
  WeaveSpec s = SatinPattern(5, 2);
  s.warp_spacing_mm = 0.16;
  s.weft_spacing_mm = 0.25;
  s.warp_width_mm = 0.16;
  s.weft_width_mm = 0.24;
  s.warp_thickness_mm = 0.05;
  s.weft_thickness_mm = 0.06;
  s.crimp_mm = 0.03;
  s.slub = 0.03;
  s.ply_depth_mm = 0.0;
  s.warp = Yarn(0.62f, 0.50f, 0.35f, 0.25f, 0.6f, 0.2f, 0.3f, 0.75f, 0.02f, 0.02f);
  s.weft = Yarn(0.55f, 0.44f, 0.30f, 0.35f, 0.6f, 0.2f, 0.3f, 0.5f, 0.02f, 0.02f);
  return s;
}

// Denim: 3/1 right-hand twill, ring-dyed indigo warp (uneven: strong thread and fibre variation,
// slubby open-end yarn) over an undyed weft.
WeaveSpec DenimSpec() {
  WeaveSpec s = TwillPattern(3, 1);
  s.warp_spacing_mm = 0.42;
  s.weft_spacing_mm = 0.60;
  s.warp_width_mm = 0.42;
  s.weft_width_mm = 0.56;
  s.warp_thickness_mm = 0.18;
  s.weft_thickness_mm = 0.16;
  s.crimp_mm = 0.08;
  s.slub = 0.15;
  s.slub_length_mm = 3.0;
  s.ply_depth_mm = 0.02;
  s.ply_pitch_mm = 0.5;
  s.twist_angle_deg = 30.0;
  s.warp = Yarn(0.035f, 0.065f, 0.20f, 0.85f, 0.4f, 0.15f, 0.3f, 0.1f, 0.25f, 0.3f);
  s.weft = Yarn(0.72f, 0.68f, 0.58f, 0.80f, 0.4f, 0.15f, 0.3f, 0.1f, 0.04f, 0.05f);
  return s;
}

// Gauze/scrim: open plain weave, yarns half the spacing wide: a quarter of the area is holes.
WeaveSpec OpenWeaveSpec() {
  WeaveSpec s = PlainPattern();
  s.warp_spacing_mm = 0.6;
  s.weft_spacing_mm = 0.6;
  s.warp_width_mm = 0.3;
  s.weft_width_mm = 0.3;
  s.warp_thickness_mm = 0.12;
  s.weft_thickness_mm = 0.12;
  s.crimp_mm = 0.06;
  s.slub = 0.1;
  s.ply_depth_mm = 0.015;
  s.ply_pitch_mm = 0.4;
  s.gaps_are_holes = true;
  s.warp = Yarn(0.70f, 0.68f, 0.60f, 0.8f, 0.5f, 0.1f, 0.5f, 0.1f, 0.05f, 0.08f);
  s.weft = s.warp;
  return s;
}

KnitSpec JerseySpec() {
  KnitSpec s;  // t-shirt jersey: ~13 wales/cm, ~18 courses/cm
  s.yarn = Yarn(0.30f, 0.30f, 0.32f, 0.85f, 0.4f, 0.25f, 0.5f, 0.2f, 0.04f, 0.25f);  // heather grey
  return s;
}

PileSpec VelvetSpec() {
  PileSpec s;  // silk/viscose velvet, ~0.6 mm cut pile, burgundy
  s.pile = Yarn(0.28f, 0.015f, 0.035f, 0.85f, 0.3f, 1.0f, 0.7f, 0.3f, 0.0f, 0.12f);
  return s;
}

LaceSpec LaceSpecDefault() {
  LaceSpec s;  // ivory cotton lace; net period along x and y = 1.8 mm, 5 per motif repeat
  s.net_spacing_mm = 1.8 / std::numbers::sqrt2;
  s.motif_spacing_mm = 9.0;
  s.cloth_spacing_mm = 0.225;  // 40 per motif repeat, so the whole pattern repeats every 9 mm
  s.net = Yarn(0.80f, 0.75f, 0.62f, 0.6f, 0.4f, 0.3f, 0.4f, 0.1f, 0.03f, 0.05f);
  s.gimp = Yarn(0.82f, 0.77f, 0.64f, 0.45f, 0.5f, 0.3f, 0.4f, 0.4f, 0.02f, 0.03f);
  return s;
}

WeaveSpec WithMaterial(WeaveSpec s, const YarnMaterial& m) {
  s.warp = m;
  s.weft = m;
  return s;
}

struct Preset {
  std::string description;
  std::function<SceneSpec(const SceneOptions&)> make;
};

const std::map<std::string, Preset>& Presets() {
  static const std::map<std::string, Preset> presets = [] {
    std::map<std::string, Preset> p;
    p["plain"] = {"cotton poplin, plain weave 0.30 x 0.32 mm, no holes",
                  [](const SceneOptions& o) { return MakeWeave(PlainSpec(), o.seed); }};
    p["twill"] = {"gabardine, 2/1 twill, warp 0.25 mm, weft 0.35 mm",
                  [](const SceneOptions& o) { return MakeWeave(TwillSpec(), o.seed); }};
    p["satin"] = {"filament satin, 5-harness warp-faced, anisotropic floats, roughness 0.25",
                  [](const SceneOptions& o) { return MakeWeave(SatinSpec(), o.seed); }};
    p["denim"] = {"denim, 3/1 twill, indigo warp over white weft, slubby",
                  [](const SceneOptions& o) { return MakeWeave(DenimSpec(), o.seed); }};
    p["knit"] = {"single jersey face, V stitches 0.8 x 0.6 mm, heather grey",
                 [](const SceneOptions& o) { return MakeKnit(JerseySpec(), o.seed); }};
    p["velvet"] = {"cut pile velvet 0.6 mm, sheen 1, crushed regions",
                   [](const SceneOptions& o) { return MakePile(VelvetSpec(), o.seed); }};
    p["velvet_mismatch"] = {"velvet rendered with the cloth lobe the fitter does not model",
                            [](const SceneOptions& o) {
                              SceneSpec s = MakePile(VelvetSpec(), o.seed);
                              s.reflectance = ReflectanceModel::kClothMismatch;
                              return s;
                            }};
    p["lace"] = {"diamond net with holes, flower motifs of cloth-work, raised gimp",
                 [](const SceneOptions& o) { return MakeLace(LaceSpecDefault(), o.seed); }};
    p["dark"] = {"plain weave, albedo 0.01: signal near the noise floor",
                 [](const SceneOptions& o) { return MakeWeave(WithMaterial(PlainSpec(), Uniform(0.01f, 0.7f, 0.5f)), o.seed); }};
    p["bright"] = {"plain weave, white albedo 1: saturates the sensor",
                   [](const SceneOptions& o) { return MakeWeave(WithMaterial(PlainSpec(), Uniform(1.0f, 0.6f, 0.5f)), o.seed); }};
    p["mirror"] = {"plain weave, roughness 0.02: near-mirror highlights",
                   [](const SceneOptions& o) { return MakeWeave(WithMaterial(PlainSpec(), Uniform(0.3f, 0.02f, 0.5f)), o.seed); }};
    p["pure_velvet"] = {"velvet geometry, sheen 1 and nothing else (black base, specular 0)",
                        [](const SceneOptions& o) {
                          YarnMaterial m = Uniform(0.0f, 1.0f, 0.0f);
                          m.sheen = 1.0f;
                          PileSpec s = VelvetSpec();
                          s.pile = m;
                          return MakePile(s, o.seed);
                        }};
    p["holes"] = {"open plain weave (gauze), 25 % holes",
                  [](const SceneOptions& o) { return MakeWeave(OpenWeaveSpec(), o.seed); }};
    p["flat_lambertian"] = {"flat plane, albedo 0.5, roughness 1, specular 0: the analytic reference",
                            [](const SceneOptions&) { return MakeFlat(Uniform(0.5f, 1.0f, 0.0f)); }};
    p["sphere_cap"] = {"one spherical cap centred on the grid: closed-form normals",
                       [](const SceneOptions& o) { return MakeSphereCap(Uniform(0.5f, 1.0f, 0.0f), o); }};
    p["velvet_bumps"] = {"the velvet's material, uniform, on the egg-crate bumps: every lobe of the velvet on a "
                         "smooth relief (one normal per pixel holds)",
                         [](const SceneOptions&) {
                           YarnMaterial m = VelvetSpec().pile;
                           m.thread_color_variation = m.fibre_color_variation = m.thread_roughness_variation = 0.0f;
                           return MakeBumps(m);
                         }};
    p["bumps"] = {"egg-crate bumps, period 2 mm, 0.3 mm deep: closed-form normals",
                  [](const SceneOptions&) { return MakeBumps(Uniform(0.5f, 1.0f, 0.0f)); }};
    return p;
  }();
  return presets;
}

}  // namespace
}  // namespace internal

bool SceneOptions::Check() const {
  return width >= 1 && height >= 1 && std::isfinite(pitch_mm) && pitch_mm > 0.0 && std::isfinite(origin_x_mm) &&
         std::isfinite(origin_y_mm);
}

std::vector<std::string> SceneNames() {
  // The fabric presets first, then the extreme and analytic ones.
  std::vector<std::string> names = {"plain", "twill", "satin", "knit", "denim", "velvet", "lace"};
  for (const auto& [name, preset] : internal::Presets()) {
    if (std::find(names.begin(), names.end(), name) == names.end()) names.push_back(name);
  }
  return names;
}

const char* ReflectanceModelName(ReflectanceModel model) {
  return model == ReflectanceModel::kClothMismatch ? "cloth_mismatch" : "principled";
}

namespace {
constexpr ReflectanceModel kReflectanceModels[] = {ReflectanceModel::kPrincipled, ReflectanceModel::kClothMismatch};
}  // namespace

bool ParseReflectanceModel(const std::string& name, ReflectanceModel* model) {
  for (ReflectanceModel m : kReflectanceModels) {
    if (name == ReflectanceModelName(m)) {
      *model = m;
      return true;
    }
  }
  return false;
}

std::string ReflectanceModelChoices() {
  std::string out;
  for (ReflectanceModel m : kReflectanceModels) {
    out += std::string(out.empty() ? "" : " or ") + "\"" + ReflectanceModelName(m) + "\"";
  }
  return out;
}

SceneTruth MakeScene(const std::string& name, const SceneOptions& options) {
  const auto& presets = internal::Presets();
  const auto it = presets.find(name);
  if (it == presets.end()) throw std::invalid_argument("MakeScene: unknown scene '" + name + "'");
  if (!options.Check()) {
    throw std::invalid_argument("MakeScene: need width, height >= 1 and a positive pitch_mm");
  }
  internal::SceneSpec spec = it->second.make(options);
  const internal::SurfaceModel& model = *spec.model;

  const int w = options.width, h = options.height;
  const double pitch = options.pitch_mm;
  const double x0 = options.origin_x_mm, y0 = options.origin_y_mm;
  SceneTruth truth;
  truth.name = name;
  truth.pitch_mm = pitch;
  truth.seed = options.seed;
  truth.model = spec.reflectance;
  // The maps hold float heights: round the declared bounds outward to float so they hold exactly.
  truth.height_min_mm = std::nextafter(static_cast<float>(spec.height_min_mm), -HUGE_VALF);
  truth.height_max_mm = std::nextafter(static_cast<float>(spec.height_max_mm), HUGE_VALF);
  truth.repeat_x_mm = spec.repeat_x_mm;
  truth.repeat_y_mm = spec.repeat_y_mm;
  truth.description = it->second.description;
  truth.yarns = spec.yarns;
  for (Image* image : {&truth.height_mm, &truth.roughness, &truth.specular, &truth.specular_tint, &truth.sheen,
                       &truth.sheen_tint, &truth.metallic, &truth.anisotropic, &truth.alpha}) {
    *image = Image(w, h, 1, 0.0f, pitch);
  }
  for (Image* image : {&truth.normal, &truth.base_color, &truth.tangent}) *image = Image(w, h, 3, 0.0f, pitch);

  // Pass 1: sample the fabric at every pixel centre. The in-plane fibre direction goes into the
  // tangent map for now; pass 2 turns it into a unit tangent orthogonal to the normal.
  ParallelFor(static_cast<std::size_t>(h), [&](std::size_t begin, std::size_t end) {
    for (auto row = static_cast<int>(begin); row < static_cast<int>(end); ++row) {
      const double y = y0 + PixelYMm(row, pitch);
      for (int col = 0; col < w; ++col) {
        const internal::SurfacePoint p = model.Evaluate(x0 + PixelXMm(col, pitch), y);
        truth.height_mm.at(0, row, col) = p.height_mm;
        for (int c = 0; c < 3; ++c) truth.base_color.at(c, row, col) = p.base_color[c];
        truth.roughness.at(0, row, col) = p.roughness;
        truth.specular.at(0, row, col) = p.specular;
        truth.specular_tint.at(0, row, col) = p.specular_tint;
        truth.sheen.at(0, row, col) = p.sheen;
        truth.sheen_tint.at(0, row, col) = p.sheen_tint;
        truth.metallic.at(0, row, col) = p.metallic;
        truth.anisotropic.at(0, row, col) = p.anisotropic;
        truth.alpha.at(0, row, col) = p.alpha;
        truth.tangent.at(0, row, col) = p.tangent_x;
        truth.tangent.at(1, row, col) = p.tangent_y;
      }
    }
  });

  // Pass 2: normals of the height field by central differences with the grid pitch (x right,
  // y up, so the row above is +y). Beyond the border the model itself gives the height, so border
  // normals are central differences too.
  const Image& hm = truth.height_mm;
  auto height_at = [&](int row, int col) -> double {
    if (row >= 0 && row < h && col >= 0 && col < w) return hm.at(0, row, col);
    // Same float rounding as the in-grid samples, so a border normal equals an interior one.
    return static_cast<float>(model.HeightMm(x0 + PixelXMm(col, pitch), y0 + PixelYMm(row, pitch)));
  };
  ParallelFor(static_cast<std::size_t>(h), [&](std::size_t begin, std::size_t end) {
    for (auto row = static_cast<int>(begin); row < static_cast<int>(end); ++row) {
      for (int col = 0; col < w; ++col) {
        const double dh_dx = (height_at(row, col + 1) - height_at(row, col - 1)) / (2.0 * pitch);
        const double dh_dy = (height_at(row - 1, col) - height_at(row + 1, col)) / (2.0 * pitch);
        const double inv = 1.0 / std::sqrt(dh_dx * dh_dx + dh_dy * dh_dy + 1.0);
        const double nx = -dh_dx * inv, ny = -dh_dy * inv, nz = inv;
        truth.normal.at(0, row, col) = static_cast<float>(nx);
        truth.normal.at(1, row, col) = static_cast<float>(ny);
        truth.normal.at(2, row, col) = static_cast<float>(nz);
        // Gram-Schmidt: the in-plane fibre direction projected onto the tangent plane. Never
        // degenerate: its length is at least nz > 0 for a unit in-plane direction.
        double tx = truth.tangent.at(0, row, col), ty = truth.tangent.at(1, row, col);
        const double tl = std::hypot(tx, ty);
        if (tl > 0.0) {
          tx /= tl;
          ty /= tl;
        } else {
          tx = 1.0;
          ty = 0.0;
        }
        const double dot = tx * nx + ty * ny;
        double px = tx - dot * nx, py = ty - dot * ny, pz = -dot * nz;
        const double pl = std::sqrt(px * px + py * py + pz * pz);
        truth.tangent.at(0, row, col) = static_cast<float>(px / pl);
        truth.tangent.at(1, row, col) = static_cast<float>(py / pl);
        truth.tangent.at(2, row, col) = static_cast<float>(pz / pl);
      }
    }
  });
  return truth;
}

SceneOptions OversampledSceneOptions(const SceneOptions& coarse, int factor) {
  if (factor < 1) throw std::invalid_argument("OversampledSceneOptions: factor must be >= 1");
  if (factor == 1) return coarse;
  SceneOptions fine = coarse;
  fine.width = coarse.width * factor;
  fine.height = coarse.height * factor;
  fine.pitch_mm = coarse.pitch_mm / factor;
  // Fine pixel 0 is centred half a fine pitch inside the coarse pixel's left (top) edge.
  const double shift = (0.5 / factor - 0.5) * coarse.pitch_mm;
  fine.origin_x_mm = coarse.origin_x_mm + shift;
  fine.origin_y_mm = coarse.origin_y_mm - shift;
  return fine;
}

namespace {

// Box average of factor x factor blocks, every channel.
Image BlockAverage(const Image& fine, int factor, double coarse_pitch) {
  if (fine.empty()) return Image();
  const int w = fine.width() / factor, h = fine.height() / factor, ch = fine.channels();
  Image out(w, h, ch, 0.0f, coarse_pitch);
  const double inv = 1.0 / (static_cast<double>(factor) * factor);
  ParallelFor(static_cast<std::size_t>(h), [&](std::size_t begin, std::size_t end) {
    for (auto row = static_cast<int>(begin); row < static_cast<int>(end); ++row) {
      for (int c = 0; c < ch; ++c) {
        for (int col = 0; col < w; ++col) {
          double sum = 0.0;
          for (int j = 0; j < factor; ++j) {
            for (int i = 0; i < factor; ++i) sum += fine.at(c, row * factor + j, col * factor + i);
          }
          out.at(c, row, col) = static_cast<float>(sum * inv);
        }
      }
    }
  });
  return out;
}

}  // namespace

SceneTruth AreaAverageScene(const SceneTruth& fine, int factor) {
  if (factor < 1) throw std::invalid_argument("AreaAverageScene: factor must be >= 1");
  if (factor == 1) return fine;
  const int fw = fine.height_mm.width(), fh = fine.height_mm.height();
  if (fw % factor != 0 || fh % factor != 0) {
    throw std::invalid_argument("AreaAverageScene: a " + std::to_string(fw) + "x" + std::to_string(fh) +
                                " grid is not a whole number of " + std::to_string(factor) + "x blocks");
  }
  SceneTruth t;
  t.name = fine.name;
  t.pitch_mm = fine.pitch_mm * factor;
  t.seed = fine.seed;
  t.model = fine.model;
  t.height_min_mm = fine.height_min_mm;
  t.height_max_mm = fine.height_max_mm;
  t.repeat_x_mm = fine.repeat_x_mm;
  t.repeat_y_mm = fine.repeat_y_mm;
  t.description = fine.description;
  t.yarns = fine.yarns;
  for (auto member : {&SceneTruth::height_mm, &SceneTruth::normal, &SceneTruth::base_color, &SceneTruth::roughness,
                      &SceneTruth::specular, &SceneTruth::specular_tint, &SceneTruth::sheen, &SceneTruth::sheen_tint,
                      &SceneTruth::metallic, &SceneTruth::anisotropic, &SceneTruth::alpha, &SceneTruth::tangent}) {
    t.*member = BlockAverage(fine.*member, factor, t.pitch_mm);
  }
  // Unit normals (the mean of unit vectors is shorter than one), tangents orthogonal to them.
  if (!t.normal.empty()) {
    const int w = t.normal.width(), h = t.normal.height();
    ParallelFor(static_cast<std::size_t>(h), [&](std::size_t begin, std::size_t end) {
      for (auto row = static_cast<int>(begin); row < static_cast<int>(end); ++row) {
        for (int col = 0; col < w; ++col) {
          double n[3] = {t.normal.at(0, row, col), t.normal.at(1, row, col), t.normal.at(2, row, col)};
          const double nl = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
          if (nl > 1e-12) {
            for (double& v : n) v /= nl;
          } else {
            n[0] = n[1] = 0.0, n[2] = 1.0;
          }
          for (int c = 0; c < 3; ++c) t.normal.at(c, row, col) = static_cast<float>(n[c]);
          if (t.tangent.empty()) continue;
          double tv[3] = {t.tangent.at(0, row, col), t.tangent.at(1, row, col), t.tangent.at(2, row, col)};
          const double dot = tv[0] * n[0] + tv[1] * n[1] + tv[2] * n[2];
          for (int c = 0; c < 3; ++c) tv[c] -= dot * n[c];
          double tl = std::sqrt(tv[0] * tv[0] + tv[1] * tv[1] + tv[2] * tv[2]);
          if (tl < 1e-6) {  // fibres crossing at right angles cancel: fall back to +x in the plane
            tv[0] = 1.0 - n[0] * n[0], tv[1] = -n[0] * n[1], tv[2] = -n[0] * n[2];
            tl = std::sqrt(tv[0] * tv[0] + tv[1] * tv[1] + tv[2] * tv[2]);
          }
          for (int c = 0; c < 3; ++c) t.tangent.at(c, row, col) = static_cast<float>(tv[c] / tl);
        }
      }
    });
  }
  return t;
}

}  // namespace u3mscan::synthetic
