#pragma once
// Tiny synthetic stacks for the fitting tests, rendered here with the core BRDF (not with the
// fitter's own code paths): a bumpy height field on a metric grid, per-pixel Principled parameters
// from a material function, directional or point lights, an overhead and optionally an oblique
// camera.
//
// Shading frame convention (docs/fitting.md): z = normal, x = world +x projected into the tangent
// plane. World: z toward the overhead camera, lengths in mm.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cmath>
#include <functional>
#include <string>
#include <vector>

#include "core/image.h"
#include "core/principled_brdf.h"
#include "core/stack.h"
#include "fitting/principled_fit.h"

namespace u3mscan::fitting::testing {

inline constexpr double kDegToRad = 3.14159265358979323846 / 180.0;

using MaterialFn = std::function<PrincipledParams<double>(int col, int row)>;

// Reflectance model of the render. kCharlieSheen is the model-mismatch case of the issue: Disney's
// sheen replaced by the Estevez-Kulla "Charlie" sheen (SIGGRAPH 2017) with the Neubelt-Pettineo
// cloth visibility, the second model of the synthetic scanner (datasets_synthetic/renderer.h),
// written here again from the papers so that the fitting tests stay independent of that library.
enum class RenderModel { kPrincipled, kCharlieSheen };

struct SceneSpec {
  int width = 16;
  int height = 16;
  double pitch_mm = 0.1;
  // Height field h = amplitude * sin(2 pi x / period) * cos(2 pi y / period') in mm: normals tilt
  // up to atan(2 pi amplitude / period) ~ 27 degrees here, so highlights land on some pixels for
  // many lights.
  double bump_amplitude_mm = 0.08;
  double bump_period_mm = 1.0;
  // Directional lights: (elevation above the horizon, azimuth) in degrees.
  std::vector<std::pair<double, double>> lights_deg;
  bool oblique_view = false;
  double oblique_view_deg = 60.0;  // camera angle from the sample normal, azimuth 0 (+x side)
  // Values at or above this are clipped and flagged kSaturated (<= 0: no saturation).
  double white_level = 0.0;
  // > 0: point lights at this distance (mm) from the grid centre in the directions above, with a
  // cos^2 emission profile aimed at the centre; rgb then scales with 1/d^2 (core LightModel).
  double point_light_distance_mm = 0.0;
  RenderModel model = RenderModel::kPrincipled;
  MaterialFn material;
  // Fibre direction of the render (degrees from the fit's tangent convention, world +x projected,
  // turned about the normal) per pixel; empty: 0 everywhere, the fit's own convention. A twill's
  // warp runs at 90 degrees to its weft.
  std::function<double(int col, int row)> tangent_deg;
  // > 1: every pixel is this many facets along each side, each with the bump field's normal at its
  // own centre, and a camera photographs their mixture, each facet weighted by the area it sees of
  // it, max(0, n.v) / n_z (fitting/facet_mixture.h). The geometry's normals are then the facets'
  // normalised mean (the area-average normal photometric stereo gives) and its fine_normals the
  // facets' (fine_factor = this).
  int facets_per_pixel = 0;
};

// Overhead rig: 16 lights on four rings (elevation 15, 35, 55, 75 degrees).
inline std::vector<std::pair<double, double>> OverheadLights() {
  std::vector<std::pair<double, double>> out;
  const double elevations[] = {15.0, 35.0, 55.0, 75.0};
  for (int ring = 0; ring < 4; ++ring) {
    for (int k = 0; k < 4; ++k) out.push_back({elevations[ring], 90.0 * k + 22.5 * ring});
  }
  return out;
}

// Lights that graze from the side opposite the oblique camera (azimuth 180 degrees).
inline std::vector<std::pair<double, double>> GrazingLights() {
  return {{10.0, 180.0}, {20.0, 160.0}, {20.0, 200.0}, {30.0, 180.0}};
}

// Both: with the oblique view, the rig that makes sheen measurable.
inline std::vector<std::pair<double, double>> OverheadAndGrazingLights() {
  std::vector<std::pair<double, double>> out = OverheadLights();
  for (const auto& l : GrazingLights()) out.push_back(l);
  return out;
}

struct Scene {
  Stack stack;
  SurfaceGeometry geometry;
  std::vector<PrincipledParams<double>> truth;  // per pixel, row-major
};

inline double HeightMm(const SceneSpec& s, double x, double y) {
  const double k = 2.0 * 3.14159265358979323846 / s.bump_period_mm;
  return s.bump_amplitude_mm * std::sin(k * x) * std::cos(0.8 * k * y);
}

inline Eigen::Vector3d NormalAt(const SceneSpec& s, double x, double y) {
  const double k = 2.0 * 3.14159265358979323846 / s.bump_period_mm;
  const double dhdx = s.bump_amplitude_mm * k * std::cos(k * x) * std::cos(0.8 * k * y);
  const double dhdy = -s.bump_amplitude_mm * 0.8 * k * std::sin(k * x) * std::sin(0.8 * k * y);
  return Eigen::Vector3d(-dhdx, -dhdy, 1.0).normalized();
}

inline Eigen::Vector3d LightDirection(double elevation_deg, double azimuth_deg) {
  const double e = elevation_deg * kDegToRad, a = azimuth_deg * kDegToRad;
  return {std::cos(e) * std::cos(a), std::cos(e) * std::sin(a), std::sin(e)};
}

// Charlie sheen roughness floor: the distribution is undefined at 0 (Estevez and Kulla clamp too).
inline constexpr double kMinCharlieRoughness = 0.07;

// f of the chosen model (1/sr), L and V unit in the local frame.
inline Vec3<double> EvaluateModel(RenderModel model, const PrincipledParams<double>& params, const Vec3<double>& l,
                                  const Vec3<double>& v) {
  if (model == RenderModel::kPrincipled) return EvaluatePrincipled(params, l, v);
  if (!(l.z() > 0.0) || !(v.z() > 0.0)) return Vec3<double>::Zero();
  PrincipledParams<double> base = params;
  base.sheen = 0.0;
  const Vec3<double> h = (l + v).normalized();
  const double r = std::max(kMinCharlieRoughness, params.roughness);
  // D = (2 + 1/r) sin(theta_h)^(1/r) / (2 pi); V = 1 / (4 (cos_l + cos_v - cos_l cos_v)).
  const double sin2 = std::max(0.0, 1.0 - h.z() * h.z());
  const double d = (2.0 + 1.0 / r) * std::pow(sin2, 0.5 / r) / (2.0 * 3.14159265358979323846);
  const double vis = 1.0 / (4.0 * (l.z() + v.z() - l.z() * v.z()));
  const Vec3<double> tint = brdf::Mix(Vec3<double>(1, 1, 1), brdf::TintColor(params.base_color), params.sheen_tint);
  return EvaluatePrincipled(base, l, v) + tint * (params.sheen * d * vis * (1.0 - params.metallic));
}

// Renders one observation with the core BRDF: rgb = f * cos_l * E (E = 1 for directional lights).
inline Observation RenderObservation(const Scene& scene, const SceneSpec& spec, int view, int light) {
  const Stack& stack = scene.stack;
  Observation o;
  o.view = view;
  o.light = light;
  o.rgb = Image(spec.width, spec.height, 3, 0.0f, spec.pitch_mm);
  o.flags.assign(static_cast<std::size_t>(spec.width) * spec.height, 0);
  // f cos_l E of one facet of unit normal n.
  auto shade = [&](int col, int row, const Eigen::Vector3d& n, const Eigen::Vector3d& lw, const Eigen::Vector3d& vw,
                   double irradiance) {
    const Eigen::Vector3d t0 = (Eigen::Vector3d::UnitX() - n.x() * n).normalized();
    const double turn = spec.tangent_deg ? spec.tangent_deg(col, row) * kDegToRad : 0.0;
    const Eigen::Vector3d t = std::cos(turn) * t0 + std::sin(turn) * n.cross(t0);
    const Eigen::Vector3d b = n.cross(t);
    const Vec3<double> l(lw.dot(t), lw.dot(b), lw.dot(n));
    const Vec3<double> v(vw.dot(t), vw.dot(b), vw.dot(n));
    const auto& params = scene.truth[static_cast<std::size_t>(row) * spec.width + col];
    return Vec3<double>(EvaluateModel(spec.model, params, l, v) * (std::max(0.0, l.z()) * irradiance));
  };
  const int k = spec.facets_per_pixel;
  for (int row = 0; row < spec.height; ++row) {
    for (int col = 0; col < spec.width; ++col) {
      const Eigen::Vector3d p = stack.grid.PixelCentreInWorld(col, row);
      const double h = scene.geometry.height_mm.at(0, row, col);
      const Eigen::Vector3d point(p.x(), p.y(), h);
      const Eigen::Vector3d n(scene.geometry.normals.at(0, row, col), scene.geometry.normals.at(1, row, col),
                              scene.geometry.normals.at(2, row, col));
      const Eigen::Vector3d lw = stack.lights[light].DirectionFrom(point);
      const double irradiance = stack.lights[light].RelativeIrradianceAt(point);
      const Eigen::Vector3d vw = (stack.views[view].centre_in_world_mm - point).normalized();
      Vec3<double> rgb = Vec3<double>::Zero();
      if (k > 1) {
        double seen = 0.0;
        for (int j = 0; j < k; ++j) {
          for (int i = 0; i < k; ++i) {
            const Image& fine = scene.geometry.fine_normals;
            const Eigen::Vector3d nf(fine.at(0, row * k + j, col * k + i), fine.at(1, row * k + j, col * k + i),
                                     fine.at(2, row * k + j, col * k + i));
            const double w = std::max(0.0, nf.dot(vw)) / nf.z();
            rgb += w * shade(col, row, nf.normalized(), lw, vw, irradiance);
            seen += w;
          }
        }
        rgb /= seen;
      } else {
        rgb = shade(col, row, n, lw, vw, irradiance);
      }
      bool saturated = false;
      for (int c = 0; c < 3; ++c) {
        double value = rgb(c);
        if (spec.white_level > 0.0 && value >= spec.white_level) {
          value = spec.white_level;
          saturated = true;
        }
        o.rgb.at(c, row, col) = static_cast<float>(value);
      }
      if (saturated) o.flags[static_cast<std::size_t>(row) * spec.width + col] |= kSaturated;
    }
  }
  return o;
}

// Builds the scene and renders every (view, light) pair.
inline Scene MakeScene(const SceneSpec& spec) {
  Scene scene;
  Stack& stack = scene.stack;
  stack.grid.width = spec.width;
  stack.grid.height = spec.height;
  stack.grid.pitch_mm = spec.pitch_mm;
  stack.grid.x0_mm = 0.0;
  stack.grid.y1_mm = spec.height * spec.pitch_mm;
  const Eigen::Vector3d centre(0.5 * spec.width * spec.pitch_mm, 0.5 * spec.height * spec.pitch_mm, 0.0);
  stack.views.push_back({"top", centre + Eigen::Vector3d(0, 0, 1000.0)});
  if (spec.oblique_view) {
    const double a = spec.oblique_view_deg * kDegToRad;
    stack.views.push_back({"oblique", centre + 1000.0 * Eigen::Vector3d(std::sin(a), 0.0, std::cos(a))});
  }
  for (std::size_t i = 0; i < spec.lights_deg.size(); ++i) {
    LightModel light;
    light.id = "L";  // (not "L" + to_string: GCC 12 reports a false -Wrestrict on it)
    light.id += std::to_string(i);
    light.type = LightType::kDirectional;
    light.direction_in_world = LightDirection(spec.lights_deg[i].first, spec.lights_deg[i].second);
    if (spec.point_light_distance_mm > 0.0) {
      light.type = LightType::kPoint;
      light.position_in_world_mm = centre + spec.point_light_distance_mm * light.direction_in_world;
      light.has_profile = true;
      light.profile_axis_in_world = -light.direction_in_world;
      light.profile_exponent = 2.0;
    }
    stack.lights.push_back(light);
  }
  scene.geometry.normals = Image(spec.width, spec.height, 3, 0.0f, spec.pitch_mm);
  scene.geometry.height_mm = Image(spec.width, spec.height, 1, 0.0f, spec.pitch_mm);
  scene.geometry.albedo = Image(spec.width, spec.height, 3, 0.0f, spec.pitch_mm);
  const int k = spec.facets_per_pixel;
  if (k > 1) {
    scene.geometry.fine_normals = Image(k * spec.width, k * spec.height, 3, 0.0f, spec.pitch_mm / k);
    scene.geometry.fine_factor = k;
  }
  for (int row = 0; row < spec.height; ++row) {
    for (int col = 0; col < spec.width; ++col) {
      const Eigen::Vector3d p = stack.grid.PixelCentreInWorld(col, row);
      Eigen::Vector3d n = NormalAt(spec, p.x(), p.y());
      if (k > 1) {  // facet (i, j) centred at its place in the pixel (rows run toward -y)
        Eigen::Vector3d sum = Eigen::Vector3d::Zero();
        for (int j = 0; j < k; ++j) {
          for (int i = 0; i < k; ++i) {
            const Eigen::Vector3d nf = NormalAt(spec, p.x() + ((i + 0.5) / k - 0.5) * spec.pitch_mm,
                                                p.y() - ((j + 0.5) / k - 0.5) * spec.pitch_mm);
            for (int c = 0; c < 3; ++c) scene.geometry.fine_normals.at(c, row * k + j, col * k + i) = static_cast<float>(nf(c));
            sum += nf;
          }
        }
        n = sum.normalized();
      }
      for (int c = 0; c < 3; ++c) scene.geometry.normals.at(c, row, col) = static_cast<float>(n(c));
      scene.geometry.height_mm.at(0, row, col) = static_cast<float>(HeightMm(spec, p.x(), p.y()));
      const PrincipledParams<double> params = spec.material(col, row);
      for (int c = 0; c < 3; ++c) scene.geometry.albedo.at(c, row, col) = static_cast<float>(params.base_color(c));
      scene.truth.push_back(params);
    }
  }
  for (int view = 0; view < static_cast<int>(stack.views.size()); ++view) {
    for (int light = 0; light < static_cast<int>(stack.lights.size()); ++light) {
      stack.observations.push_back(RenderObservation(scene, spec, view, light));
    }
  }
  return scene;
}

// sqrt(sum (a - b)^2 / sum b^2) over all channels and pixels.
inline double RelativeRmse(const Image& a, const Image& b) {
  double e = 0.0, d = 0.0;
  for (std::size_t i = 0; i < a.data().size(); ++i) {
    const double t = a.data()[i] - b.data()[i];
    e += t * t;
    d += static_cast<double>(b.data()[i]) * b.data()[i];
  }
  return d > 0.0 ? std::sqrt(e / d) : 0.0;
}

}  // namespace u3mscan::fitting::testing
