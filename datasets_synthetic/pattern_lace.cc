// Lace: a diamond net (threads at +-45 deg, knotted where they cross) with holes between the
// threads, and a square lattice of six-petal flower motifs: dense cloth-work inside, a raised gimp
// cord around the outline, and a gimp-ringed eyelet (a hole) in the centre.

#include <algorithm>
#include <cmath>
#include <numbers>

#include "datasets_synthetic/pattern_noise.h"
#include "datasets_synthetic/scene_internal.h"

namespace u3mscan::synthetic::internal {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kPetals = 6.0;
constexpr double kPetalDepth = 0.12;      // relative radius modulation of the flower outline
constexpr double kEyeletRadiusMm = 0.55;  // hole in the motif centre
constexpr double kEyeletRingMm = 0.8;     // centre line of the gimp ring around it
constexpr double kNetSlub = 0.1;          // relative thickness variation between net threads

class LaceModel final : public SurfaceModel {
 public:
  LaceModel(const LaceSpec& spec, std::uint64_t seed) : spec_(spec), seed_(seed) {}

  SurfacePoint Evaluate(double x_mm, double y_mm) const override {
    SurfacePoint p;
    const double m = spec_.motif_spacing_mm;
    const double cx = m * (std::floor(x_mm / m) + 0.5), cy = m * (std::floor(y_mm / m) + 0.5);
    const double dx = x_mm - cx, dy = y_mm - cy;
    const double r = std::sqrt(dx * dx + dy * dy);
    const double theta = std::atan2(dy, dx);
    const double outline = spec_.motif_radius_mm * (1.0 + kPetalDepth * std::cos(kPetals * theta));
    const double half_gimp = 0.5 * spec_.gimp_width_mm;
    const auto motif_x = static_cast<std::int64_t>(std::floor(x_mm / m));
    const auto motif_y = static_cast<std::int64_t>(std::floor(y_mm / m));
    const auto fibre = static_cast<float>(ValueNoise2(seed_, kFibre, x_mm / 0.05, y_mm / 0.05));

    // Gimp: the outline and the eyelet ring (the outline distance is radial, close enough to the
    // true distance for a cord at this petal depth).
    const double gimp_dist = std::min(std::abs(r - outline), std::abs(r - kEyeletRingMm));
    if (gimp_dist < half_gimp) {
      const double q = gimp_dist / half_gimp;
      ApplyYarn(spec_.gimp, HashUnit(seed_, kLaceColor, motif_x, motif_y), HashUnit(seed_, kLaceColor2, motif_x, motif_y),
                fibre, &p);
      p.height_mm = static_cast<float>(spec_.net_thickness_mm + spec_.gimp_thickness_mm * std::sqrt(1.0 - q * q));
      p.tangent_x = static_cast<float>(-std::sin(theta));  // along the ring
      p.tangent_y = static_cast<float>(std::cos(theta));
      return p;
    }
    if (r < kEyeletRadiusMm) return Hole();
    if (r < outline) {
      // Cloth-work: a fine, dense weave-like relief (period cloth_spacing) on top of the net plane.
      ApplyYarn(spec_.net, HashUnit(seed_, kLaceColor, motif_x, motif_y), HashUnit(seed_, kLaceColor2, motif_x, motif_y),
                fibre, &p);
      const double k = 2.0 * kPi / spec_.cloth_spacing_mm;
      const double relief = 0.75 + 0.25 * std::cos(k * x_mm) * std::cos(k * y_mm);
      p.height_mm = static_cast<float>(1.5 * spec_.net_thickness_mm * relief);
      return p;
    }
    // Net: distance to the nearest thread of each family, threads along (1, -1) and (1, 1).
    const double n = spec_.net_spacing_mm, half_net = 0.5 * spec_.net_width_mm;
    const double u = (x_mm + y_mm) / std::numbers::sqrt2, v = (x_mm - y_mm) / std::numbers::sqrt2;
    const double du = u - n * std::round(u / n), dv = v - n * std::round(v / n);
    const double cu = std::abs(du) < half_net ? std::sqrt(1.0 - (du / half_net) * (du / half_net)) : 0.0;
    const double cv = std::abs(dv) < half_net ? std::sqrt(1.0 - (dv / half_net) * (dv / half_net)) : 0.0;
    if (cu <= 0.0 && cv <= 0.0) return Hole();
    const auto thread = static_cast<std::int64_t>(std::round(cu >= cv ? u / n : v / n));
    ApplyYarn(spec_.net, HashUnit(seed_, kLaceColor, thread, cu >= cv ? 0 : 1),
              HashUnit(seed_, kLaceColor2, thread, cu >= cv ? 0 : 1), fibre, &p);
    // Thread-to-thread thickness (+-kNetSlub). Where two threads cross their crowns add up: the
    // twisted knot of a bobbin net.
    const auto iu = static_cast<std::int64_t>(std::round(u / n)), iv = static_cast<std::int64_t>(std::round(v / n));
    const double su = 1.0 + kNetSlub * (2.0 * HashUnit(seed_, kLaceSlub, iu, 0) - 1.0);
    const double sv = 1.0 + kNetSlub * (2.0 * HashUnit(seed_, kLaceSlub, iv, 1) - 1.0);
    p.height_mm = static_cast<float>(spec_.net_thickness_mm * (su * cu + sv * cv));
    const double inv = 1.0 / std::numbers::sqrt2;
    p.tangent_x = static_cast<float>(inv);
    p.tangent_y = static_cast<float>(cu >= cv ? -inv : inv);
    return p;
  }

  double MaxHeightMm() const {
    return std::max({spec_.net_thickness_mm + spec_.gimp_thickness_mm, 2.0 * (1.0 + kNetSlub) * spec_.net_thickness_mm,
                     1.5 * spec_.net_thickness_mm});
  }

 private:
  SurfacePoint Hole() const {
    SurfacePoint p;
    ApplyYarn(spec_.net, 0.5f, 0.5f, 0.0f, &p);
    p.alpha = 0.0f;
    p.height_mm = 0.0f;
    return p;
  }

  LaceSpec spec_;
  std::uint64_t seed_;
};

}  // namespace

SceneSpec MakeLace(const LaceSpec& spec, std::uint64_t seed) {
  auto model = std::make_unique<LaceModel>(spec, seed);
  SceneSpec out;
  out.height_min_mm = 0.0;
  out.height_max_mm = model->MaxHeightMm();
  out.repeat_x_mm = spec.motif_spacing_mm;
  out.repeat_y_mm = spec.motif_spacing_mm;
  out.yarns.push_back(ToYarnTruth("net", spec.net, spec.net_width_mm, spec.net_thickness_mm, spec.net_spacing_mm));
  out.yarns.push_back(ToYarnTruth("gimp", spec.gimp, spec.gimp_width_mm, spec.gimp_thickness_mm, 0.0));
  out.model = std::move(model);
  return out;
}

}  // namespace u3mscan::synthetic::internal
