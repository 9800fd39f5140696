// Cut pile (velvet): a dense carpet of fibre tips. Height = pile height + fibre-tip noise (fine
// fBm) - crushed regions (coarse noise); the pile leans in a slowly varying direction, which is
// the axis of anisotropy, and leans further where it is crushed.

#include <algorithm>
#include <cmath>
#include <numbers>

#include "datasets_synthetic/pattern_noise.h"
#include "datasets_synthetic/scene_internal.h"

namespace u3mscan::synthetic::internal {
namespace {

class PileModel final : public SurfaceModel {
 public:
  PileModel(const PileSpec& spec, std::uint64_t seed) : spec_(spec), seed_(seed) {}

  SurfacePoint Evaluate(double x_mm, double y_mm) const override {
    const double crush = Crush(x_mm, y_mm);
    SurfacePoint p;
    p.height_mm = static_cast<float>(Height(x_mm, y_mm, crush));
    // Per-tuft colour: tufts ~0.1 mm, below the pixel at 300 dpi, so this reads as fibre noise.
    const auto tuft_x = static_cast<std::int64_t>(std::floor(x_mm / 0.1));
    const auto tuft_y = static_cast<std::int64_t>(std::floor(y_mm / 0.1));
    const float fibre = 2.0f * HashUnit(seed_, kFibre, tuft_x, tuft_y) - 1.0f;
    ApplyYarn(spec_.pile, 0.5f, 0.5f, fibre, &p);
    // Crushed pile lies flatter along its lean: more anisotropic, a little less sheen.
    p.anisotropic = std::clamp(static_cast<float>(spec_.pile.anisotropic + 0.4 * crush), 0.0f, 1.0f);
    p.sheen = std::clamp(static_cast<float>(spec_.pile.sheen * (1.0 - 0.2 * crush)), 0.0f, 1.0f);
    const double angle = std::numbers::pi * ValueNoise2(seed_, kPileLean, x_mm / 10.0, y_mm / 10.0);
    p.tangent_x = static_cast<float>(std::cos(angle));
    p.tangent_y = static_cast<float>(std::sin(angle));
    return p;
  }

  double HeightMm(double x_mm, double y_mm) const override { return Height(x_mm, y_mm, Crush(x_mm, y_mm)); }

 private:
  // 0 (upright) .. 1 (fully crushed).
  double Crush(double x_mm, double y_mm) const {
    const double n = ValueNoise2(seed_, kPileCrush, x_mm / spec_.crush_scale_mm, y_mm / spec_.crush_scale_mm);
    return std::clamp(1.5 * n, 0.0, 1.0);
  }
  double Height(double x_mm, double y_mm, double crush) const {
    const double tips = Fbm2(seed_, kPileTips, x_mm / spec_.tip_scale_mm, y_mm / spec_.tip_scale_mm, 3);
    return spec_.pile_height_mm + spec_.tip_roughness_mm * tips - spec_.crush_mm * crush;
  }

  PileSpec spec_;
  std::uint64_t seed_;
};

}  // namespace

SceneSpec MakePile(const PileSpec& spec, std::uint64_t seed) {
  SceneSpec out;
  out.model = std::make_unique<PileModel>(spec, seed);
  out.height_min_mm = spec.pile_height_mm - spec.tip_roughness_mm - spec.crush_mm;
  out.height_max_mm = spec.pile_height_mm + spec.tip_roughness_mm;
  out.yarns.push_back(ToYarnTruth("pile", spec.pile, 0.1, spec.pile_height_mm, 0.1));
  return out;
}

}  // namespace u3mscan::synthetic::internal
