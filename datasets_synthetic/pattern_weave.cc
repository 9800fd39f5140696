// Woven fabrics: warp threads along y, weft threads along x, crossing over and under each other as
// the weave's warp-over matrix says. Each yarn is a rounded (elliptical) cross-section whose axis
// rises over a crossing and sinks under one, with slubs (thickness variation along the yarn),
// twisted-ply grooves on the crown, and per-thread colour.
//
// Fabric coordinates: s = x_mm (across warps), t = -y_mm (down the sample, across wefts), so warp i
// covers s in [i, i+1) * warp_spacing and weft j covers t in [j, j+1) * weft_spacing.

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <numeric>
#include <stdexcept>
#include <utility>

#include "datasets_synthetic/pattern_noise.h"
#include "datasets_synthetic/scene_internal.h"

namespace u3mscan::synthetic::internal {
namespace {

constexpr double kPi = std::numbers::pi;

// Smooth 0 -> 1 over a half period of a cosine: a yarn's axis passes from over to under with zero
// slope at each crossing centre, as a bent fibre bundle does.
double CosineStep(double f) { return 0.5 - 0.5 * std::cos(kPi * f); }

std::int64_t FloorIndex(double v) { return static_cast<std::int64_t>(std::floor(v)); }

int Mod(std::int64_t a, int n) {
  const auto r = static_cast<int>(a % n);
  return r < 0 ? r + n : r;
}

class WeaveModel final : public SurfaceModel {
 public:
  WeaveModel(WeaveSpec spec, std::uint64_t seed) : spec_(std::move(spec)), seed_(seed) {
    floor_mm_ = -spec_.crimp_mm - spec_.ply_depth_mm;
  }

  SurfacePoint Evaluate(double x_mm, double y_mm) const override {
    const double s = x_mm, t = -y_mm;
    const Yarn warp = WarpAt(s, t);
    const Yarn weft = WeftAt(s, t);
    SurfacePoint p;
    const Yarn* top = nullptr;
    if (warp.present && (!weft.present || warp.height_mm >= weft.height_mm)) {
      top = &warp;
    } else if (weft.present) {
      top = &weft;
    }
    if (top == nullptr) {
      // No yarn here: a hole through an open weave, or the shadowed back of a dense one.
      if (spec_.gaps_are_holes) {
        ApplyYarn(spec_.weft, 0.5f, 0.5f, 0.0f, &p);
        p.alpha = 0.0f;
        p.height_mm = 0.0f;
      } else {
        ApplyYarn(spec_.weft, weft.color_u0, weft.color_u1, 0.0f, &p);
        p.height_mm = 0.0f;
      }
      p.tangent_x = 1.0f;
      p.tangent_y = 0.0f;
      return p;
    }
    const bool is_warp = top == &warp;
    // Fibres are long: colour noise stretched along the yarn (1 mm) and fine across it (0.04 mm).
    const double along = is_warp ? t : s, across = is_warp ? s : t;
    const auto fibre = static_cast<float>(ValueNoise2(seed_, kFibre + (is_warp ? 0u : 1u), along / 1.0, across / 0.04));
    ApplyYarn(is_warp ? spec_.warp : spec_.weft, top->color_u0, top->color_u1, fibre, &p);
    p.height_mm = static_cast<float>(top->height_mm - floor_mm_);
    // Warp axis runs along -y in fabric coordinates; the sign of a tangent does not matter to the BRDF.
    p.tangent_x = is_warp ? 0.0f : 1.0f;
    p.tangent_y = is_warp ? 1.0f : 0.0f;
    return p;
  }

  // Bounds of Evaluate's heights (mm): floor at 0, crowns at most crimp + thickness * (1 + slub).
  double MaxHeightMm() const {
    const double thick = std::max(spec_.warp_thickness_mm, spec_.weft_thickness_mm) * (1.0 + spec_.slub);
    return spec_.crimp_mm + thick - floor_mm_;
  }

 private:
  struct Yarn {
    bool present = false;
    double height_mm = -std::numeric_limits<double>::infinity();
    float color_u0 = 0.5f, color_u1 = 0.5f;
  };

  bool WarpOver(std::int64_t i, std::int64_t j) const {
    return spec_.warp_over[Mod(j, spec_.repeat_weft) * spec_.repeat_warp + Mod(i, spec_.repeat_warp)] != 0;
  }

  // Height of one yarn at a point: axis level (interpolated between its crossings) + rounded crown
  // scaled by the slub, minus the ply grooves that wind around the crown at the twist angle.
  double YarnHeight(double level_mm, double across_mm, double half_width_mm, double thickness_mm, double along_mm,
                    double ply_phase) const {
    const double q = across_mm / half_width_mm;
    const double crown = std::sqrt(std::max(0.0, 1.0 - q * q));
    double h = level_mm + thickness_mm * crown;
    if (spec_.ply_depth_mm > 0.0) {
      const double slant = std::tan(spec_.twist_angle_deg * kPi / 180.0);
      const double phase = (along_mm + across_mm * slant) / spec_.ply_pitch_mm + ply_phase;
      // Grooves are deepest on the crown and fade toward the edges where the yarn turns away.
      h -= spec_.ply_depth_mm * crown * (0.5 + 0.5 * std::cos(2.0 * kPi * phase));
    }
    return h;
  }

  Yarn WarpAt(double s, double t) const {
    Yarn y;
    const std::int64_t i = FloorIndex(s / spec_.warp_spacing_mm);
    const double across = s - (static_cast<double>(i) + 0.5) * spec_.warp_spacing_mm;
    const double half = 0.5 * spec_.warp_width_mm;
    y.color_u0 = HashUnit(seed_, kWarpColor, i);
    y.color_u1 = HashUnit(seed_, kWarpColor2, i);
    if (std::abs(across) >= half) return y;
    // Axis level between the crossings with wefts j0 and j0 + 1 (crossing centres at (j + 0.5) * spacing).
    const double g = t / spec_.weft_spacing_mm - 0.5;
    const std::int64_t j0 = FloorIndex(g);
    const double l0 = WarpOver(i, j0) ? spec_.crimp_mm : -spec_.crimp_mm;
    const double l1 = WarpOver(i, j0 + 1) ? spec_.crimp_mm : -spec_.crimp_mm;
    const double level = l0 + (l1 - l0) * CosineStep(g - static_cast<double>(j0));
    const double slub = 1.0 + spec_.slub * ValueNoise1(seed_, kWarpSlub, i, t / spec_.slub_length_mm);
    y.present = true;
    y.height_mm = YarnHeight(level, across, half, spec_.warp_thickness_mm * slub, t, y.color_u1);
    return y;
  }

  Yarn WeftAt(double s, double t) const {
    Yarn y;
    const std::int64_t j = FloorIndex(t / spec_.weft_spacing_mm);
    const double across = t - (static_cast<double>(j) + 0.5) * spec_.weft_spacing_mm;
    const double half = 0.5 * spec_.weft_width_mm;
    y.color_u0 = HashUnit(seed_, kWeftColor, j);
    y.color_u1 = HashUnit(seed_, kWeftColor2, j);
    if (std::abs(across) >= half) return y;
    const double g = s / spec_.warp_spacing_mm - 0.5;
    const std::int64_t i0 = FloorIndex(g);
    const double l0 = WarpOver(i0, j) ? -spec_.crimp_mm : spec_.crimp_mm;
    const double l1 = WarpOver(i0 + 1, j) ? -spec_.crimp_mm : spec_.crimp_mm;
    const double level = l0 + (l1 - l0) * CosineStep(g - static_cast<double>(i0));
    const double slub = 1.0 + spec_.slub * ValueNoise1(seed_, kWeftSlub, j, s / spec_.slub_length_mm);
    y.present = true;
    y.height_mm = YarnHeight(level, across, half, spec_.weft_thickness_mm * slub, s, y.color_u1);
    return y;
  }

  WeaveSpec spec_;
  std::uint64_t seed_;
  double floor_mm_ = 0.0;
};

}  // namespace

WeaveSpec PlainPattern() {
  WeaveSpec spec;
  spec.repeat_warp = 2;
  spec.repeat_weft = 2;
  spec.warp_over = {1, 0, 0, 1};
  return spec;
}

WeaveSpec TwillPattern(int over, int under) {
  if (over < 1 || under < 1) throw std::invalid_argument("TwillPattern: over and under must be >= 1");
  WeaveSpec spec;
  const int n = over + under;
  spec.repeat_warp = n;
  spec.repeat_weft = n;
  spec.warp_over.assign(static_cast<std::size_t>(n * n), 0);
  // Warp i is over wefts i .. i + over - 1 (mod n): the floats step by one weft per warp, which
  // draws the twill's diagonal.
  for (int i = 0; i < n; ++i) {
    for (int k = 0; k < over; ++k) spec.warp_over[static_cast<std::size_t>(((i + k) % n) * n + i)] = 1;
  }
  return spec;
}

WeaveSpec SatinPattern(int harness, int move) {
  if (harness < 5 || move < 2 || move >= harness - 1 || std::gcd(harness, move) != 1) {
    throw std::invalid_argument("SatinPattern: need harness >= 5 and 1 < move < harness - 1 coprime to it");
  }
  WeaveSpec spec;
  spec.repeat_warp = harness;
  spec.repeat_weft = harness;
  spec.warp_over.assign(static_cast<std::size_t>(harness * harness), 1);
  // Warp-faced: each warp goes under exactly one weft, the binding points scattered by `move`
  // so no diagonal forms and the long warp floats make the smooth, anisotropic face.
  for (int i = 0; i < harness; ++i) spec.warp_over[static_cast<std::size_t>(((i * move) % harness) * harness + i)] = 0;
  return spec;
}

SceneSpec MakeWeave(const WeaveSpec& spec, std::uint64_t seed) {
  if (spec.repeat_warp < 1 || spec.repeat_weft < 1 ||
      spec.warp_over.size() != static_cast<std::size_t>(spec.repeat_warp * spec.repeat_weft)) {
    throw std::logic_error("MakeWeave: warp_over must hold repeat_warp * repeat_weft entries");
  }
  if (!(spec.warp_spacing_mm > 0 && spec.weft_spacing_mm > 0 && spec.warp_width_mm > 0 && spec.weft_width_mm > 0 &&
        spec.ply_pitch_mm > 0 && spec.slub_length_mm > 0 && spec.slub >= 0 && spec.slub < 1)) {
    throw std::logic_error("MakeWeave: spacings, widths, pitches must be positive and slub in [0, 1)");
  }
  auto model = std::make_unique<WeaveModel>(spec, seed);
  SceneSpec out;
  out.height_min_mm = 0.0;
  out.height_max_mm = model->MaxHeightMm();
  out.repeat_x_mm = spec.repeat_warp * spec.warp_spacing_mm;
  out.repeat_y_mm = spec.repeat_weft * spec.weft_spacing_mm;
  out.yarns.push_back(ToYarnTruth("warp", spec.warp, spec.warp_width_mm, spec.warp_thickness_mm, spec.warp_spacing_mm));
  out.yarns.push_back(ToYarnTruth("weft", spec.weft, spec.weft_width_mm, spec.weft_thickness_mm, spec.weft_spacing_mm));
  out.model = std::move(model);
  return out;
}

}  // namespace u3mscan::synthetic::internal
