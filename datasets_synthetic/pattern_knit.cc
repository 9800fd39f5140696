// Single jersey, technical face: columns (wales) of V-shaped stitches. Each stitch shows two legs,
// yarn segments leaning inward that meet at the bottom of the V; a leg rises toward its middle and
// dips at its ends, where it passes under the neighbouring loops. The legs of one course nest into
// those of the next, so every pixel takes the highest of the legs of the 3 x 3 stitches around it.
//
// Fabric coordinates: s = x_mm (across wales), t = -y_mm (down the courses).

#include <algorithm>
#include <cmath>
#include <numbers>

#include "datasets_synthetic/pattern_noise.h"
#include "datasets_synthetic/scene_internal.h"

namespace u3mscan::synthetic::internal {
namespace {

constexpr double kPi = std::numbers::pi;
// Leg end points in units of the stitch cell (u across the wale, v down the course). Legs reach
// 15 % into the courses above and below: that overlap is the nesting of the loops.
constexpr double kLegTopU = 0.10, kLegBottomU = 0.47, kLegTopV = -0.15, kLegBottomV = 1.15;

class KnitModel final : public SurfaceModel {
 public:
  KnitModel(const KnitSpec& spec, std::uint64_t seed) : spec_(spec), seed_(seed) {}

  SurfacePoint Evaluate(double x_mm, double y_mm) const override {
    const double s = x_mm, t = -y_mm;
    const Leg leg = HighestLeg(s, t);
    SurfacePoint p;
    const auto fibre = static_cast<float>(ValueNoise2(seed_, kFibre, x_mm / 0.06, y_mm / 0.06));
    // One yarn runs along a course: its colour (dye lot, barré) varies course by course.
    ApplyYarn(spec_.yarn, HashUnit(seed_, kKnitColor, leg.course), HashUnit(seed_, kKnitColor2, leg.course),
              fibre, &p);
    p.height_mm = static_cast<float>(std::max(0.0, leg.height_mm));
    p.tangent_x = static_cast<float>(leg.dir_s);
    p.tangent_y = static_cast<float>(-leg.dir_t);
    return p;
  }

  double MaxHeightMm() const { return spec_.loop_lift_mm + spec_.yarn_thickness_mm * (1.0 + kSlub); }

 private:
  static constexpr double kSlub = 0.08;  // relative yarn thickness variation between stitches

  struct Leg {
    double height_mm = 0.0;  // floor (the back loops) when no leg covers the point
    std::int64_t course = 0;
    double dir_s = 1.0, dir_t = 0.0;  // unit direction of the leg, fabric coordinates
  };

  Leg HighestLeg(double s, double t) const {
    const double w = spec_.wale_spacing_mm, c = spec_.course_spacing_mm;
    const auto k0 = static_cast<std::int64_t>(std::floor(s / w));
    const auto m0 = static_cast<std::int64_t>(std::floor(t / c));
    Leg best;
    best.course = m0;
    const double half = 0.5 * spec_.yarn_width_mm;
    for (std::int64_t m = m0 - 1; m <= m0 + 1; ++m) {
      for (std::int64_t k = k0 - 1; k <= k0 + 1; ++k) {
        const double cell_s = static_cast<double>(k) * w, cell_t = static_cast<double>(m) * c;
        const double slub = 1.0 + kSlub * (2.0 * HashUnit(seed_, kKnitSlub, k, m) - 1.0);
        for (int side = 0; side < 2; ++side) {
          // Left leg leans right going down, right leg mirrors it.
          const double top_u = side == 0 ? kLegTopU : 1.0 - kLegTopU;
          const double bottom_u = side == 0 ? kLegBottomU : 1.0 - kLegBottomU;
          const double as = cell_s + top_u * w, at = cell_t + kLegTopV * c;
          const double bs = cell_s + bottom_u * w, bt = cell_t + kLegBottomV * c;
          const double ds = bs - as, dt = bt - at;
          const double len2 = ds * ds + dt * dt;
          const double tau = std::clamp(((s - as) * ds + (t - at) * dt) / len2, 0.0, 1.0);
          const double ps = s - (as + tau * ds), pt = t - (at + tau * dt);
          const double dist = std::sqrt(ps * ps + pt * pt);
          if (dist >= half) continue;
          const double crown = std::sqrt(1.0 - (dist / half) * (dist / half));
          const double len = std::sqrt(len2);
          // Signed distance across the leg, for the slant of the ply grooves.
          const double across = (ps * dt - pt * ds) / len;
          const double along = tau * len;
          double h = spec_.loop_lift_mm * std::sin(kPi * tau) + spec_.yarn_thickness_mm * slub * crown;
          const double phase = (along + across * std::tan(kPi / 6.0)) / spec_.ply_pitch_mm;
          h -= spec_.ply_depth_mm * crown * (0.5 + 0.5 * std::cos(2.0 * kPi * phase));
          if (h > best.height_mm) {
            best.height_mm = h;
            best.course = m;
            best.dir_s = ds / len;
            best.dir_t = dt / len;
          }
        }
      }
    }
    return best;
  }

  KnitSpec spec_;
  std::uint64_t seed_;
};

}  // namespace

SceneSpec MakeKnit(const KnitSpec& spec, std::uint64_t seed) {
  auto model = std::make_unique<KnitModel>(spec, seed);
  SceneSpec out;
  out.height_min_mm = 0.0;
  out.height_max_mm = model->MaxHeightMm();
  out.repeat_x_mm = spec.wale_spacing_mm;
  out.repeat_y_mm = spec.course_spacing_mm;
  out.yarns.push_back(
      ToYarnTruth("yarn", spec.yarn, spec.yarn_width_mm, spec.yarn_thickness_mm, spec.wale_spacing_mm));
  out.model = std::move(model);
  return out;
}

}  // namespace u3mscan::synthetic::internal
