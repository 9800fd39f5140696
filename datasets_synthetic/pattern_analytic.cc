// Analytic presets: a flat plane, an egg-crate of bumps and a spherical cap, each with one constant
// material; heights and normals in closed form (scene_analytic.h).

#include <algorithm>
#include <cmath>
#include <numbers>

#include "datasets_synthetic/scene_analytic.h"
#include "datasets_synthetic/scene_internal.h"

namespace u3mscan::synthetic {
namespace {
constexpr double kTwoPi = 2.0 * std::numbers::pi;

std::array<double, 3> NormalFromSlopes(double dh_dx, double dh_dy) {
  const double norm = std::sqrt(dh_dx * dh_dx + dh_dy * dh_dy + 1.0);
  return {-dh_dx / norm, -dh_dy / norm, 1.0 / norm};
}
}  // namespace

double BumpsHeightMm(double x_mm, double y_mm) {
  const double k = kTwoPi / kBumpsPeriodMm;
  return kBumpsAmplitudeMm * (1.0 + std::cos(k * x_mm) * std::cos(k * y_mm));
}

std::array<double, 3> BumpsNormal(double x_mm, double y_mm) {
  const double k = kTwoPi / kBumpsPeriodMm;
  const double dh_dx = -kBumpsAmplitudeMm * k * std::sin(k * x_mm) * std::cos(k * y_mm);
  const double dh_dy = -kBumpsAmplitudeMm * k * std::cos(k * x_mm) * std::sin(k * y_mm);
  return NormalFromSlopes(dh_dx, dh_dy);
}

SphereCap SphereCapFor(const SceneOptions& options) {
  SphereCap cap;
  cap.center_x_mm = options.origin_x_mm + PixelXMm(0, options.pitch_mm) + 0.5 * (options.width - 1) * options.pitch_mm;
  cap.center_y_mm = options.origin_y_mm + PixelYMm(0, options.pitch_mm) - 0.5 * (options.height - 1) * options.pitch_mm;
  cap.base_radius_mm = 0.4 * std::min(options.width, options.height) * options.pitch_mm;
  cap.cap_height_mm = std::min(1.0, 0.25 * cap.base_radius_mm);
  cap.sphere_radius_mm = (cap.base_radius_mm * cap.base_radius_mm + cap.cap_height_mm * cap.cap_height_mm) /
                         (2.0 * cap.cap_height_mm);
  return cap;
}

double SphereCapHeightMm(const SphereCap& cap, double x_mm, double y_mm) {
  const double dx = x_mm - cap.center_x_mm, dy = y_mm - cap.center_y_mm;
  const double r2 = dx * dx + dy * dy;
  if (r2 >= cap.base_radius_mm * cap.base_radius_mm) return 0.0;
  const double R = cap.sphere_radius_mm;
  return std::max(0.0, std::sqrt(R * R - r2) - (R - cap.cap_height_mm));
}

std::array<double, 3> SphereCapNormal(const SphereCap& cap, double x_mm, double y_mm) {
  const double dx = x_mm - cap.center_x_mm, dy = y_mm - cap.center_y_mm;
  if (dx * dx + dy * dy >= cap.base_radius_mm * cap.base_radius_mm) return {0.0, 0.0, 1.0};
  // On a sphere the normal is the radius direction from the sphere's centre (below the plane).
  const double R = cap.sphere_radius_mm;
  const double dz = SphereCapHeightMm(cap, x_mm, y_mm) + (R - cap.cap_height_mm);
  return {dx / R, dy / R, dz / R};
}

namespace internal {
namespace {

void ApplyConstant(const YarnMaterial& m, SurfacePoint* p) { ApplyYarn(m, 0.5f, 0.5f, 0.0f, p); }

class FlatModel final : public SurfaceModel {
 public:
  explicit FlatModel(const YarnMaterial& m) : material_(m) {}
  SurfacePoint Evaluate(double, double) const override {
    SurfacePoint p;
    ApplyConstant(material_, &p);
    p.height_mm = 0.0f;
    return p;
  }
  double HeightMm(double, double) const override { return 0.0; }

 private:
  YarnMaterial material_;
};

class BumpsModel final : public SurfaceModel {
 public:
  explicit BumpsModel(const YarnMaterial& m) : material_(m) {}
  SurfacePoint Evaluate(double x_mm, double y_mm) const override {
    SurfacePoint p;
    ApplyConstant(material_, &p);
    p.height_mm = static_cast<float>(BumpsHeightMm(x_mm, y_mm));
    return p;
  }
  double HeightMm(double x_mm, double y_mm) const override { return BumpsHeightMm(x_mm, y_mm); }

 private:
  YarnMaterial material_;
};

class SphereCapModel final : public SurfaceModel {
 public:
  SphereCapModel(const YarnMaterial& m, const SphereCap& cap) : material_(m), cap_(cap) {}
  SurfacePoint Evaluate(double x_mm, double y_mm) const override {
    SurfacePoint p;
    ApplyConstant(material_, &p);
    p.height_mm = static_cast<float>(SphereCapHeightMm(cap_, x_mm, y_mm));
    return p;
  }
  double HeightMm(double x_mm, double y_mm) const override { return SphereCapHeightMm(cap_, x_mm, y_mm); }

 private:
  YarnMaterial material_;
  SphereCap cap_;
};

}  // namespace

SceneSpec MakeFlat(const YarnMaterial& material) {
  SceneSpec out;
  out.model = std::make_unique<FlatModel>(material);
  out.yarns.push_back(ToYarnTruth("surface", material, 0, 0, 0));
  return out;
}

SceneSpec MakeBumps(const YarnMaterial& material) {
  SceneSpec out;
  out.model = std::make_unique<BumpsModel>(material);
  out.height_max_mm = 2.0 * kBumpsAmplitudeMm;
  out.repeat_x_mm = out.repeat_y_mm = kBumpsPeriodMm;
  out.yarns.push_back(ToYarnTruth("surface", material, 0, 0, 0));
  return out;
}

SceneSpec MakeSphereCap(const YarnMaterial& material, const SceneOptions& options) {
  const SphereCap cap = SphereCapFor(options);
  SceneSpec out;
  out.model = std::make_unique<SphereCapModel>(material, cap);
  out.height_max_mm = cap.cap_height_mm;
  out.yarns.push_back(ToYarnTruth("surface", material, 0, 0, 0));
  return out;
}

}  // namespace internal
}  // namespace u3mscan::synthetic
