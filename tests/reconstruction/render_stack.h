#pragma once
// Test helper: renders tiny Stacks of an analytic height field under given lights, Lambertian or
// with the core Principled BRDF, with optional noise, clipping and cast shadows. Frames and units
// as in core/stack.h (world z up toward the camera, mm).

#include <Eigen/Geometry>
#include <cmath>
#include <functional>
#include <numbers>
#include <optional>
#include <random>
#include <vector>

#include "core/principled_brdf.h"
#include "core/stack.h"

namespace u3mscan::reconstruction::testing {

struct HeightField {
  std::function<double(double, double)> z;  // mm at world (x, y) mm
  std::function<double(double, double)> dzdx;
  std::function<double(double, double)> dzdy;

  Eigen::Vector3d Normal(double x, double y) const { return Eigen::Vector3d(-dzdx(x, y), -dzdy(x, y), 1.0).normalized(); }
};

inline HeightField Flat() {
  return {[](double, double) { return 0.0; }, [](double, double) { return 0.0; }, [](double, double) { return 0.0; }};
}

// Bumps z = a sin(kx x) cos(ky y), zero mean over whole periods. Max tilt = atan(a k).
inline HeightField Bumps(double amplitude_mm, double wavelength_mm) {
  const double k = 2 * std::numbers::pi / wavelength_mm, a = amplitude_mm;
  return {[=](double x, double y) { return a * std::sin(k * x) * std::cos(k * y); },
          [=](double x, double y) { return a * k * std::cos(k * x) * std::cos(k * y); },
          [=](double x, double y) { return -a * k * std::sin(k * x) * std::sin(k * y); }};
}

inline MetricGrid Grid(int w, int h, double pitch_mm) {
  MetricGrid g;
  g.width = w, g.height = h, g.pitch_mm = pitch_mm;
  g.x0_mm = -0.5 * w * pitch_mm;  // centred on the world origin
  g.y1_mm = 0.5 * h * pitch_mm;
  return g;
}

inline LightModel Directional(double azimuth_deg, double elevation_deg) {
  const double a = azimuth_deg * std::numbers::pi / 180, e = elevation_deg * std::numbers::pi / 180;
  LightModel l;
  l.type = LightType::kDirectional;
  l.direction_in_world = Eigen::Vector3d(std::cos(e) * std::cos(a), std::cos(e) * std::sin(a), std::sin(e));
  return l;
}

// A point light at distance_mm from the origin, aimed at it with a cos^exponent profile.
inline LightModel Point(double azimuth_deg, double elevation_deg, double distance_mm, double exponent = 1.0) {
  LightModel l = Directional(azimuth_deg, elevation_deg);
  l.type = LightType::kPoint;
  l.position_in_world_mm = l.direction_in_world * distance_mm;
  l.has_profile = exponent > 0.0;
  l.profile_axis_in_world = -l.direction_in_world;
  l.profile_exponent = exponent;
  return l;
}

// A ring of lights: `count` azimuths, elevations alternating between the two given.
template <typename Make>
std::vector<LightModel> Ring(int count, double elev_a, double elev_b, Make make) {
  std::vector<LightModel> lights;
  for (int i = 0; i < count; ++i) lights.push_back(make(360.0 * i / count + 10.0, i % 2 ? elev_a : elev_b));
  return lights;
}

struct RenderOptions {
  // Per-pixel linear RGB reflectance (Lambertian albedo, or Principled base colour).
  std::function<Eigen::Vector3d(int col, int row)> albedo = [](int, int) { return Eigen::Vector3d(0.6, 0.45, 0.3); };
  std::optional<PrincipledParams<double>> principled;  // base_color overridden by `albedo`
  double noise_sigma = 0.0;             // Gaussian noise on rgb, in shading units times E
  double clip_level = 0.0;              // > 0: values clipped here (in rgb units), like a sensor
  bool flag_clipped = false;            // set kSaturated where clipped
  // Cast shadow of light k at pixel: multiplies that light's signal by 0.05 when true.
  std::function<bool(int light, int col, int row)> cast_shadow;
  bool measured_irradiance = false;     // fill Observation::irradiance with E on the plane z = 0
  std::uint32_t seed = 1;
};

inline Stack RenderStack(const MetricGrid& grid, const std::vector<LightModel>& lights, const HeightField& surface,
                         const RenderOptions& options = RenderOptions()) {
  Stack stack;
  stack.grid = grid;
  stack.lights = lights;
  stack.views.push_back(ViewGeometry{});
  std::mt19937 rng(options.seed);
  std::normal_distribution<double> noise(0.0, 1.0);
  const Eigen::Vector3d camera = stack.views[0].centre_in_world_mm;
  for (std::size_t k = 0; k < lights.size(); ++k) {
    Observation ob;
    ob.view = 0;
    ob.light = static_cast<int>(k);
    ob.rgb = Image(grid.width, grid.height, 3, 0.0f, grid.pitch_mm);
    if (options.measured_irradiance) ob.irradiance = Image(grid.width, grid.height, 1, 0.0f, grid.pitch_mm);
    if (options.flag_clipped) ob.flags.assign(static_cast<std::size_t>(grid.width) * grid.height, 0);
    for (int r = 0; r < grid.height; ++r)
      for (int c = 0; c < grid.width; ++c) {
        const Eigen::Vector3d p0 = grid.PixelCentreInWorld(c, r);
        const Eigen::Vector3d x = grid.PixelCentreInWorld(c, r, surface.z(p0.x(), p0.y()));
        const Eigen::Vector3d n = surface.Normal(p0.x(), p0.y());
        const Eigen::Vector3d l = lights[k].DirectionFrom(x);
        const double e = lights[k].RelativeIrradianceAt(x);
        const Eigen::Vector3d rho = options.albedo(c, r);
        Eigen::Vector3d rgb;
        if (options.principled) {
          // Local frame with z = n.
          const Eigen::Quaterniond q = Eigen::Quaterniond::FromTwoVectors(n, Eigen::Vector3d::UnitZ());
          PrincipledParams<double> p = *options.principled;
          p.base_color = rho;
          const Eigen::Vector3d v = (camera - x).normalized();
          rgb = EvaluatePrincipled(p, Eigen::Vector3d(q * l), Eigen::Vector3d(q * v)) * std::max(0.0, n.dot(l)) * e;
        } else {
          rgb = rho / std::numbers::pi * std::max(0.0, n.dot(l)) * e;
        }
        if (options.cast_shadow && options.cast_shadow(static_cast<int>(k), c, r)) rgb *= 0.05;
        bool clipped = false;
        for (int i = 0; i < 3; ++i) {
          double v = rgb(i) + options.noise_sigma * e * noise(rng);
          if (options.clip_level > 0.0 && v >= options.clip_level) v = options.clip_level, clipped = true;
          ob.rgb.at(i, r, c) = static_cast<float>(v);
        }
        if (clipped && options.flag_clipped) ob.flags[static_cast<std::size_t>(r) * grid.width + c] = kSaturated;
        if (options.measured_irradiance) ob.irradiance.at(0, r, c) = static_cast<float>(lights[k].RelativeIrradianceAt(p0));
      }
    stack.observations.push_back(std::move(ob));
  }
  return stack;
}

// Angle in degrees between the recovered normal at (c, r) and the surface's.
inline double AngleErrorDeg(const Image& normal, const MetricGrid& grid, const HeightField& surface, int c, int r) {
  const Eigen::Vector3d p = grid.PixelCentreInWorld(c, r);
  const Eigen::Vector3d t = surface.Normal(p.x(), p.y());
  const Eigen::Vector3d m(normal.at(0, r, c), normal.at(1, r, c), normal.at(2, r, c));
  return std::acos(std::clamp(t.dot(m.normalized()), -1.0, 1.0)) * 180.0 / std::numbers::pi;
}

struct AngleStats {
  double mean_deg = 0.0, max_deg = 0.0;
};

inline AngleStats AngleErrors(const Image& normal, const MetricGrid& grid, const HeightField& surface) {
  AngleStats s;
  for (int r = 0; r < grid.height; ++r)
    for (int c = 0; c < grid.width; ++c) {
      const double e = AngleErrorDeg(normal, grid, surface, c, r);
      s.mean_deg += e;
      s.max_deg = std::max(s.max_deg, e);
    }
  s.mean_deg /= static_cast<double>(grid.width) * grid.height;
  return s;
}

inline bool AllFinite(const Image& image) {
  for (float v : image.data())
    if (!std::isfinite(v)) return false;
  return true;
}

}  // namespace u3mscan::reconstruction::testing
