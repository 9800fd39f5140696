#include "datasets_synthetic/rig.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>

#include "core/units.h"

namespace u3mscan::synthetic {
namespace {

// Level a white Lambertian plane at the sample centre decodes to under one light (fraction of the
// sensor's full scale): bright enough for a good signal, with head room for specular highlights.
constexpr double kWhiteLevel = 0.45;
// Room light left on during the capture, relative to one light's irradiance at the centre.
constexpr double kAmbientFraction = 0.01;
constexpr double kLightDistanceMm = 400.0;   // point lights on rings 300-500 mm from the sample
constexpr double kMinCameraHeightMm = 300.0;
constexpr double kCameraHeightPerViewSize = 1.8;  // ~31 deg field of view across the long side
constexpr double kPointEmitterRadiusMm = 8.0;
constexpr double kDirectionalEmitterRadiusDeg = 0.5;

// Uniform [lo, hi) from a 64-bit engine, spelled out so the stream is the same with every
// standard library (std::uniform_real_distribution is implementation-defined).
class Jitter {
 public:
  explicit Jitter(std::uint64_t seed) : engine_(seed) {}
  double Uniform(double lo, double hi) { return lo + (hi - lo) * static_cast<double>(engine_() >> 11) * 0x1.0p-53; }

 private:
  std::mt19937_64 engine_;
};

std::uint64_t NameHash(const std::string& name) {
  std::uint64_t h = 1469598103934665603ull;  // FNV-1a
  for (unsigned char c : name) h = (h ^ c) * 1099511628211ull;
  return h;
}

Eigen::Vector3d DirectionFromAngles(double elevation_deg, double azimuth_deg) {
  const double e = DegToRad(elevation_deg), a = DegToRad(azimuth_deg);
  return {std::cos(e) * std::cos(a), std::cos(e) * std::sin(a), std::sin(e)};
}

std::string LightId(int index) {
  char buf[16];
  std::snprintf(buf, sizeof(buf), "L%02d", index);
  return buf;
}

// The camera straight above the sample centre; image right = +x, image down = -y.
RigCamera TopCamera(const RigOptions& options, Jitter& jitter) {
  RigCamera cam;
  cam.id = "top";
  cam.width = options.width;
  cam.height = options.height;
  const double view_mm = std::max(options.width, options.height) * options.pitch_mm;
  const double height_mm = std::max(kMinCameraHeightMm, kCameraHeightPerViewSize * view_mm);
  cam.fx = height_mm / options.pitch_mm;
  cam.fy = cam.fx * (1.0 + jitter.Uniform(-0.001, 0.001));
  cam.cx = 0.5 * (options.width - 1) + jitter.Uniform(-0.01, 0.01) * options.width;
  cam.cy = 0.5 * (options.height - 1) + jitter.Uniform(-0.01, 0.01) * options.height;
  cam.distortion = {-0.04 + jitter.Uniform(-0.01, 0.01), 0.01, jitter.Uniform(-5e-4, 5e-4),
                    jitter.Uniform(-5e-4, 5e-4), 0.0};
  cam.world_from_camera << 1, 0, 0, 0, -1, 0, 0, 0, -1;
  cam.position_mm = {0, 0, height_mm};
  return cam;
}

// A camera tilted by `tilt_deg` from the normal on the -y side, looking at the origin; its image
// right stays +x so the sample keeps its orientation in both views.
RigCamera ObliqueCamera(const RigCamera& top, double tilt_deg, Jitter& jitter) {
  RigCamera cam = top;
  cam.id = "oblique";
  const double t = DegToRad(tilt_deg);
  const double distance_mm = top.position_mm.z();
  cam.position_mm = distance_mm * Eigen::Vector3d(0, -std::sin(t), std::cos(t));
  const Eigen::Vector3d x_axis(1, 0, 0);
  const Eigen::Vector3d z_axis = -cam.position_mm.normalized();
  const Eigen::Vector3d y_axis = z_axis.cross(x_axis);
  cam.world_from_camera.col(0) = x_axis;
  cam.world_from_camera.col(1) = y_axis;
  cam.world_from_camera.col(2) = z_axis;
  cam.cx = 0.5 * (top.width - 1) + jitter.Uniform(-0.01, 0.01) * top.width;
  cam.cy = 0.5 * (top.height - 1) + jitter.Uniform(-0.01, 0.01) * top.height;
  cam.distortion = {-0.06 + jitter.Uniform(-0.01, 0.01), 0.02, jitter.Uniform(-5e-4, 5e-4),
                    jitter.Uniform(-5e-4, 5e-4), 0.0};
  return cam;
}

Eigen::Vector3d RgbJitter(Jitter& jitter) {
  return {1.0 + jitter.Uniform(-0.06, 0.06), 1.0 + jitter.Uniform(-0.03, 0.03), 1.0 + jitter.Uniform(-0.06, 0.06)};
}

// Irradiance at the sample centre that makes a white plane facing the light read `level`.
double CentreIrradiance(double exposure_s, double level) { return level * kPi / exposure_s; }

RigLight DirectionalLight(int index, double elevation_deg, double azimuth_deg, double flat_level,
                          double exposure_s, Jitter& jitter) {
  RigLight light;
  light.id = LightId(index);
  light.type = RigLightType::kDirectional;
  light.direction = DirectionFromAngles(elevation_deg, azimuth_deg).normalized();
  // flat_level is what a horizontal white plane reads: divide by cos(elevation).
  const double e0 = CentreIrradiance(exposure_s, flat_level) / std::max(0.05, light.direction.z());
  light.intensity_rgb = e0 * RgbJitter(jitter);
  light.emitter_radius = kDirectionalEmitterRadiusDeg;
  return light;
}

// A point light `distance_mm` from `aim_mm` at the given angles, its emitter axis toward aim_mm.
RigLight PointLight(int index, double elevation_deg, double azimuth_deg, double distance_mm,
                    const Eigen::Vector3d& aim_mm, double exponent, double flat_level, double exposure_s,
                    Jitter& jitter) {
  RigLight light;
  light.id = LightId(index);
  light.type = RigLightType::kPoint;
  light.position_mm = aim_mm + distance_mm * DirectionFromAngles(elevation_deg, azimuth_deg);
  light.profile_axis = (aim_mm - light.position_mm).normalized();
  light.profile_exponent = exponent;
  // Intensity so that a horizontal white plane at the aim point reads flat_level.
  const Eigen::Vector3d to_light = light.position_mm - aim_mm;
  const double d2 = to_light.squaredNorm();
  const double cos_i = to_light.z() / std::sqrt(d2);
  const double e0 = CentreIrradiance(exposure_s, flat_level) / std::max(0.05, cos_i);
  light.intensity_rgb = e0 * d2 * RgbJitter(jitter);
  light.emitter_radius = kPointEmitterRadiusMm;
  return light;
}

// `count` lights over the rings: each ring gets count / rings, the first count % rings rings one more.
void AddRings(Rig* rig, bool point, const std::vector<double>& elevations_deg, int count, Jitter& jitter) {
  int index = static_cast<int>(rig->lights.size());
  const int rings = static_cast<int>(elevations_deg.size());
  for (int ring = 0; ring < rings; ++ring) {
    const int per_ring = count / rings + (ring < count % rings ? 1 : 0);
    for (int k = 0; k < per_ring; ++k) {
      // Rings are offset by half a step so no two lights share an azimuth.
      const double azimuth = 360.0 * (k + 0.5 * (ring % 2)) / per_ring + jitter.Uniform(-2, 2);
      const double elevation = elevations_deg[ring] + jitter.Uniform(-2, 2);
      if (point) {
        const double distance = kLightDistanceMm + jitter.Uniform(-20, 20);
        rig->lights.push_back(PointLight(index++, elevation, azimuth, distance, Eigen::Vector3d::Zero(),
                                         2.0 + jitter.Uniform(-0.5, 1.0), kWhiteLevel, rig->exposure_s, jitter));
      } else {
        rig->lights.push_back(DirectionalLight(index++, elevation, azimuth, kWhiteLevel, rig->exposure_s, jitter));
      }
    }
  }
}

double ReferenceIrradiance(const Rig& rig) { return CentreIrradiance(rig.exposure_s, kWhiteLevel); }

}  // namespace

std::vector<std::string> RigNames() {
  return {"distant", "near", "oblique", "grazing", "coplanar", "single_light", "noisy"};
}

Rig MakeRig(const std::string& name, const RigOptions& options) {
  if (!options.Check()) throw std::invalid_argument("MakeRig: size must be at least 8x8 and pitch positive");
  Jitter jitter(options.seed * 0x9E3779B97F4A7C15ull ^ NameHash(name));
  Rig rig;
  rig.name = name;
  rig.seed = options.seed;
  rig.ground_pitch_mm = options.pitch_mm;
  rig.cameras.push_back(TopCamera(options, jitter));
  RigCamera& top = rig.cameras[0];
  auto count = [&](int preset_default) { return options.lights > 0 ? options.lights : preset_default; };

  if (name == "distant") {
    top.vignetting = VignettingModel::kCos4;
    AddRings(&rig, false, {30.0, 60.0}, count(16), jitter);
  } else if (name == "near" || name == "oblique" || name == "noisy") {
    top.vignetting = VignettingModel::kPolynomial;
    top.vignetting_poly = {-0.12, 0.02};
    AddRings(&rig, true, {30.0, 55.0}, count(16), jitter);
    if (name == "oblique") rig.cameras.push_back(ObliqueCamera(rig.cameras[0], 60.0 + jitter.Uniform(-5, 5), jitter));
    if (name == "noisy") {
      rig.sensor.full_well_e = 1500.0;
      rig.sensor.read_noise_e = 25.0;
      rig.sensor.fixed_pattern_dn = 6.0;
    }
  } else if (name == "grazing") {
    top.vignetting = VignettingModel::kCos4;
    // A horizontal white plane reads 0.15: facets tilted toward a 5 deg light get several times more.
    const int n = count(12);
    for (int k = 0; k < n; ++k) {
      rig.lights.push_back(DirectionalLight(k, 5.0, 360.0 * k / n + jitter.Uniform(-2, 2), 0.15, rig.exposure_s, jitter));
    }
  } else if (name == "coplanar") {
    top.vignetting = VignettingModel::kCos4;
    // Every direction within ~0.5 deg of the x-z plane: photometric stereo is ill-conditioned in y.
    const int n = count(12);
    for (int k = 0; k < n; ++k) {
      const double elevation = 20.0 + 140.0 * k / std::max(1, n - 1);  // 20..160 deg along the x-z great circle
      const double azimuth = (elevation <= 90.0 ? 0.0 : 180.0) + jitter.Uniform(-0.5, 0.5);
      const double e = elevation <= 90.0 ? elevation : 180.0 - elevation;
      rig.lights.push_back(DirectionalLight(k, e, azimuth, kWhiteLevel, rig.exposure_s, jitter));
    }
  } else if (name == "single_light") {
    if (options.lights != 0 && options.lights != 8) {
      throw std::invalid_argument("rig 'single_light' has exactly 8 lights (one per aim point)");
    }
    top.vignetting = VignettingModel::kPolynomial;
    top.vignetting_poly = {-0.12, 0.02};
    // Eight narrow spots, each aimed at its own part of the sample: most pixels get a usable
    // signal from one light only. Half intensity at 1/6 of the view from the aim point.
    const double view_mm = std::max(options.width, options.height) * options.pitch_mm;
    const double half_angle = std::atan(view_mm / 6.0 / kLightDistanceMm);
    const double exponent = std::log(0.5) / std::log(std::cos(half_angle));
    const double q = view_mm / 4.0;
    const Eigen::Vector3d aims[8] = {{-q, -q, 0}, {0, -q, 0}, {q, -q, 0}, {q, 0, 0},
                                     {q, q, 0},   {0, q, 0},  {-q, q, 0}, {-q, 0, 0}};
    for (int k = 0; k < 8; ++k) {
      rig.lights.push_back(PointLight(k, 40.0 + jitter.Uniform(-3, 3), 45.0 * k + 225.0, kLightDistanceMm, aims[k],
                                      exponent, kWhiteLevel, rig.exposure_s, jitter));
    }
  } else {
    throw std::invalid_argument("unknown rig '" + name + "'");
  }
  rig.ambient_irradiance = kAmbientFraction * ReferenceIrradiance(rig);
  return rig;
}

Eigen::Vector2d UndistortPixel(const RigCamera& camera, double u, double v) {
  const double xd = (u - camera.cx) / camera.fx;
  const double yd = (v - camera.cy) / camera.fy;
  const auto& k = camera.distortion;  // k1 k2 p1 p2 k3
  double x = xd, y = yd;
  // Newton on F(x, y) = distort(x, y) - (xd, yd); the Jacobian is near identity for real lenses.
  for (int it = 0; it < 20; ++it) {
    const double r2 = x * x + y * y;
    const double radial = 1 + k[0] * r2 + k[1] * r2 * r2 + k[4] * r2 * r2 * r2;
    const double dradial = k[0] + 2 * k[1] * r2 + 3 * k[4] * r2 * r2;  // d radial / d r2
    const double fx = x * radial + 2 * k[2] * x * y + k[3] * (r2 + 2 * x * x) - xd;
    const double fy = y * radial + k[2] * (r2 + 2 * y * y) + 2 * k[3] * x * y - yd;
    const double j00 = radial + x * dradial * 2 * x + 2 * k[2] * y + k[3] * 6 * x;
    const double j01 = x * dradial * 2 * y + 2 * k[2] * x + k[3] * 2 * y;
    const double j10 = y * dradial * 2 * x + k[2] * 2 * x + 2 * k[3] * y;
    const double j11 = radial + y * dradial * 2 * y + k[2] * 6 * y + 2 * k[3] * x;
    const double det = j00 * j11 - j01 * j10;
    const double dx = (j11 * fx - j01 * fy) / det;
    const double dy = (-j10 * fx + j00 * fy) / det;
    x -= dx;
    y -= dy;
    if (std::abs(dx) + std::abs(dy) < 1e-14) break;
  }
  return {x, y};
}

Eigen::Vector3d PixelRayInWorld(const RigCamera& camera, double u, double v) {
  const Eigen::Vector2d n = UndistortPixel(camera, u, v);
  return (camera.world_from_camera * Eigen::Vector3d(n.x(), n.y(), 1.0)).normalized();
}

bool ProjectToPixel(const RigCamera& camera, const Eigen::Vector3d& point_in_world, Eigen::Vector2d* pixel) {
  const Eigen::Vector3d p = camera.world_from_camera.transpose() * (point_in_world - camera.position_mm);
  if (p.z() <= 0) return false;
  const double x = p.x() / p.z(), y = p.y() / p.z();
  const auto& k = camera.distortion;
  const double r2 = x * x + y * y;
  const double radial = 1 + k[0] * r2 + k[1] * r2 * r2 + k[4] * r2 * r2 * r2;
  const double xd = x * radial + 2 * k[2] * x * y + k[3] * (r2 + 2 * x * x);
  const double yd = y * radial + k[2] * (r2 + 2 * y * y) + 2 * k[3] * x * y;
  *pixel = {camera.fx * xd + camera.cx, camera.fy * yd + camera.cy};
  return true;
}

double Vignetting(const RigCamera& camera, double u, double v) {
  switch (camera.vignetting) {
    case VignettingModel::kNone:
      return 1.0;
    case VignettingModel::kCos4: {
      const Eigen::Vector2d n = UndistortPixel(camera, u, v);
      const double cos2 = 1.0 / (1.0 + n.squaredNorm());
      return cos2 * cos2;
    }
    case VignettingModel::kPolynomial: {
      const double half_diagonal = 0.5 * std::hypot(camera.width, camera.height);
      const double r2 = ((u - camera.cx) * (u - camera.cx) + (v - camera.cy) * (v - camera.cy)) /
                        (half_diagonal * half_diagonal);
      return 1.0 + camera.vignetting_poly[0] * r2 + camera.vignetting_poly[1] * r2 * r2;
    }
  }
  return 1.0;
}

Eigen::Vector3d LightIrradiance(const RigLight& light, const Eigen::Vector3d& point_mm,
                                Eigen::Vector3d* direction_to_light) {
  if (light.type == RigLightType::kDirectional) {
    *direction_to_light = light.direction;
    return light.intensity_rgb;
  }
  const Eigen::Vector3d to_light = light.position_mm - point_mm;
  const double d2 = to_light.squaredNorm();
  const double d = std::sqrt(d2);
  *direction_to_light = to_light / d;
  double profile = 1.0;
  if (light.profile_exponent > 0) {
    const double c = std::max(0.0, -direction_to_light->dot(light.profile_axis));
    profile = std::pow(c, light.profile_exponent);
  }
  return light.intensity_rgb * (profile / d2);
}

}  // namespace u3mscan::synthetic
