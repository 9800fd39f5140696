#include "datasets_synthetic/renderer.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "core/parallel.h"
#include "core/units.h"

namespace u3mscan::synthetic {
namespace {

// Bisection steps refining a ray-march crossing: the bracket shrinks by 2^-16 of one march step
// (half a scene pixel along the plane, or the whole height range for a vertical ray): far below
// a micrometre for any preset.
constexpr int kBisectionSteps = 16;
// Charlie sheen is undefined at r = 0; Estevez and Kulla clamp the same way.
constexpr float kMinCharlieRoughness = 0.07f;

// Bilinear footprint of a world point on the scene grid.
struct Footprint {
  std::size_t i00, i01, i10, i11;  // row-major pixel indices
  float w00, w01, w10, w11;
};

class SceneGrid {
 public:
  explicit SceneGrid(const SceneTruth& scene)
      : scene_(scene), width_(scene.height_mm.width()), height_(scene.height_mm.height()), pitch_(scene.pitch_mm) {}

  double half_width_mm() const { return 0.5 * width_ * pitch_; }
  double half_height_mm() const { return 0.5 * height_ * pitch_; }

  // False outside the sample (the table).
  bool Locate(double x_mm, double y_mm, Footprint* f) const {
    if (width_ == 0 || std::abs(x_mm) > half_width_mm() || std::abs(y_mm) > half_height_mm()) return false;
    const double col = std::clamp(x_mm / pitch_ + 0.5 * width_ - 0.5, 0.0, width_ - 1.0);
    const double row = std::clamp(0.5 * height_ - 0.5 - y_mm / pitch_, 0.0, height_ - 1.0);
    const int c0 = std::min(static_cast<int>(col), width_ - 1), r0 = std::min(static_cast<int>(row), height_ - 1);
    const int c1 = std::min(c0 + 1, width_ - 1), r1 = std::min(r0 + 1, height_ - 1);
    const float fx = static_cast<float>(col - c0), fy = static_cast<float>(row - r0);
    const std::size_t w = static_cast<std::size_t>(width_);
    f->i00 = r0 * w + c0;
    f->i01 = r0 * w + c1;
    f->i10 = r1 * w + c0;
    f->i11 = r1 * w + c1;
    f->w00 = (1 - fx) * (1 - fy);
    f->w01 = fx * (1 - fy);
    f->w10 = (1 - fx) * fy;
    f->w11 = fx * fy;
    return true;
  }

  // A map that a scene left empty reads as `fallback`.
  static float Sample(const Image& map, int channel, const Footprint& f, float fallback) {
    if (map.empty()) return fallback;
    const float* p = map.plane(channel).data();
    return p[f.i00] * f.w00 + p[f.i01] * f.w01 + p[f.i10] * f.w10 + p[f.i11] * f.w11;
  }

  double Height(double x_mm, double y_mm) const {
    Footprint f;
    if (!Locate(x_mm, y_mm, &f)) return 0.0;
    return Sample(scene_.height_mm, 0, f, 0.0f);
  }

  const SceneTruth& scene() const { return scene_; }

 private:
  const SceneTruth& scene_;
  int width_, height_;
  double pitch_;
};

// The scene's fibre-direction map, when its SceneTruth has one (a `tangent` member, 3 channels).
template <typename Scene>
const Image* TangentMap(const Scene& scene) {
  if constexpr (requires { scene.tangent; }) {
    return scene.tangent.empty() ? nullptr : &scene.tangent;
  } else {
    return nullptr;
  }
}

struct SurfacePoint {
  Vec3<float> normal;
  Vec3<float> tangent = Vec3<float>::Zero();  // zero: none given
  PrincipledParams<float> params;
  float alpha = 1.0f;
};

SurfacePoint SampleSurface(const SceneTruth& s, const Footprint& f) {
  SurfacePoint sp;
  sp.normal = Vec3<float>(SceneGrid::Sample(s.normal, 0, f, 0.0f), SceneGrid::Sample(s.normal, 1, f, 0.0f),
                          SceneGrid::Sample(s.normal, 2, f, 1.0f));
  const float len = sp.normal.norm();
  sp.normal = len > 1e-6f ? Vec3<float>(sp.normal / len) : Vec3<float>(0, 0, 1);
  if (const Image* t = TangentMap(s)) {
    sp.tangent = Vec3<float>(SceneGrid::Sample(*t, 0, f, 0.0f), SceneGrid::Sample(*t, 1, f, 0.0f), SceneGrid::Sample(*t, 2, f, 0.0f));
  }
  auto& p = sp.params;
  p.base_color = Vec3<float>(SceneGrid::Sample(s.base_color, 0, f, 0.8f), SceneGrid::Sample(s.base_color, 1, f, 0.8f),
                             SceneGrid::Sample(s.base_color, 2, f, 0.8f));
  p.roughness = SceneGrid::Sample(s.roughness, 0, f, 0.5f);
  p.specular = SceneGrid::Sample(s.specular, 0, f, 0.5f);
  p.specular_tint = SceneGrid::Sample(s.specular_tint, 0, f, 0.0f);
  p.sheen = SceneGrid::Sample(s.sheen, 0, f, 0.0f);
  p.sheen_tint = SceneGrid::Sample(s.sheen_tint, 0, f, 0.0f);
  p.metallic = SceneGrid::Sample(s.metallic, 0, f, 0.0f);
  p.anisotropic = SceneGrid::Sample(s.anisotropic, 0, f, 0.0f);
  sp.alpha = std::clamp(SceneGrid::Sample(s.alpha, 0, f, 1.0f), 0.0f, 1.0f);
  return sp;
}

// Local shading frame: z = normal, x = the scene's fibre direction (the axis of anisotropy) made
// orthogonal to the normal, or world +x projected onto the tangent plane where the scene gives
// none (or it is degenerate after interpolation), y = z x x.
void LocalFrame(const Vec3<float>& n, const Vec3<float>& fibre, Vec3<float>* t, Vec3<float>* b) {
  Vec3<float> x = fibre - n * n.dot(fibre);
  if (x.squaredNorm() < 1e-6f) x = Vec3<float>(1, 0, 0) - n * n.x();
  if (x.squaredNorm() < 1e-8f) x = Vec3<float>(0, 1, 0) - n * n.y();
  *t = x.normalized();
  *b = n.cross(*t);
}

// Estevez-Kulla "Charlie" sheen distribution, D = (2 + 1/r) sin(theta_h)^(1/r) / (2 pi).
float CharlieD(float cos_h, float r) {
  const float inv_r = 1.0f / r;
  const float sin2 = std::max(0.0f, 1.0f - cos_h * cos_h);
  return (2.0f + inv_r) * std::pow(sin2, 0.5f * inv_r) / (2.0f * static_cast<float>(kPi));
}

// Neubelt and Pettineo's visibility for cloth, 1 / (4 (cos_l + cos_v - cos_l cos_v)).
float ClothVisibility(float cos_l, float cos_v) { return 1.0f / (4.0f * (cos_l + cos_v - cos_l * cos_v)); }

Vec3<float> ToVec3f(const Eigen::Vector3d& v) { return v.cast<float>(); }

// Sub-pixel ray directions: offsets of a box filter, applied in undistorted normalised coordinates
// scaled by 1/f (the distortion's change across one pixel is far below a pixel).
template <typename Body>
void ForEachSubRay(const RigCamera& cam, int col, int row, int n, Body&& body) {
  const Eigen::Vector2d c = UndistortPixel(cam, col, row);
  for (int sy = 0; sy < n; ++sy) {
    for (int sx = 0; sx < n; ++sx) {
      const double du = (sx + 0.5) / n - 0.5, dv = (sy + 0.5) / n - 0.5;
      const Eigen::Vector3d ray_cam(c.x() + du / cam.fx, c.y() + dv / cam.fy, 1.0);
      body((cam.world_from_camera * ray_cam).normalized());
    }
  }
}

void CheckCamera(const Rig& rig, int camera_index) {
  if (camera_index < 0 || camera_index >= static_cast<int>(rig.cameras.size())) {
    throw std::out_of_range("renderer: no camera " + std::to_string(camera_index));
  }
}

}  // namespace

Vec3<float> EvaluateModel(ReflectanceModel model, const PrincipledParams<float>& params, const Vec3<float>& l,
                          const Vec3<float>& v) {
  if (model == ReflectanceModel::kPrincipled) return EvaluatePrincipled(params, l, v);
  const float cos_l = l.z(), cos_v = v.z();
  if (!(cos_l > 0) || !(cos_v > 0)) return Vec3<float>::Zero();
  PrincipledParams<float> base = params;
  base.sheen = 0.0f;
  const Vec3<float> h = (l + v).normalized();
  const float r = std::max(kMinCharlieRoughness, params.roughness);
  const Vec3<float> tint = brdf::Mix(Vec3<float>(1, 1, 1), Vec3<float>(brdf::TintColor(params.base_color)), params.sheen_tint);
  const Vec3<float> sheen = tint * (params.sheen * CharlieD(h.z(), r) * ClothVisibility(cos_l, cos_v));
  return EvaluatePrincipled(base, l, v) + sheen * (1.0f - params.metallic);
}

SceneRenderer::SceneRenderer(const SceneTruth& scene, const Rig& rig, RenderOptions options)
    : scene_(scene), rig_(rig), options_(options) {
  if (scene.height_mm.empty() || scene.pitch_mm <= 0) throw std::invalid_argument("SceneRenderer: empty scene");
  half_width_mm_ = 0.5 * scene.height_mm.width() * scene.pitch_mm;
  half_height_mm_ = 0.5 * scene.height_mm.height() * scene.pitch_mm;
  const auto heights = scene.height_mm.plane(0);
  const auto [lo, hi] = std::minmax_element(heights.begin(), heights.end());
  min_height_mm_ = std::min(0.0, static_cast<double>(*lo));
  max_height_mm_ = std::max(0.0, static_cast<double>(*hi));
}

double SceneRenderer::HeightAt(double x_mm, double y_mm) const { return SceneGrid(scene_).Height(x_mm, y_mm); }

Eigen::Vector3d SceneRenderer::Trace(const Eigen::Vector3d& o, const Eigen::Vector3d& d) const {
  if (!(d.z() < 0)) return Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  const SceneGrid grid(scene_);
  const double t0 = (max_height_mm_ - o.z()) / d.z();
  const double t1 = (min_height_mm_ - o.z()) / d.z();
  if (!(t1 > t0)) return o + t0 * d;
  const double speed = std::hypot(d.x(), d.y());  // mm along the plane per unit t
  const double dt = std::min(t1 - t0, options_.march_step_pitch * scene_.pitch_mm / std::max(speed, 1e-12));
  auto f = [&](double t) {
    const Eigen::Vector3d q = o + t * d;
    return q.z() - grid.Height(q.x(), q.y());
  };
  double ta = t0;
  while (ta < t1) {
    const double tb = std::min(ta + dt, t1);
    if (f(tb) <= 0) {
      double lo = ta, hi = tb;  // f(lo) > 0 >= f(hi)
      for (int i = 0; i < kBisectionSteps; ++i) {
        const double mid = 0.5 * (lo + hi);
        (f(mid) > 0 ? lo : hi) = mid;
      }
      const Eigen::Vector3d q = o + hi * d;
      return {q.x(), q.y(), grid.Height(q.x(), q.y())};
    }
    ta = tb;
  }
  return o + t1 * d;
}

void SceneRenderer::SetCamera(int camera_index) {
  CheckCamera(rig_, camera_index);
  camera_index_ = camera_index;
  ambient_ = Image();
  const RigCamera& cam = rig_.cameras[camera_index];
  const int n = std::max(1, options_.supersample);
  rays_per_pixel_ = n * n;
  hits_.assign(static_cast<std::size_t>(cam.width) * cam.height * rays_per_pixel_ * 3, 0.0f);
  vignetting_.assign(static_cast<std::size_t>(cam.width) * cam.height, 1.0f);
  ParallelFor(cam.height, [&](std::size_t begin, std::size_t end) {
    for (std::size_t row = begin; row < end; ++row) {
      for (int col = 0; col < cam.width; ++col) {
        const std::size_t pixel = row * cam.width + col;
        float* h = &hits_[pixel * rays_per_pixel_ * 3];
        for (int sy = 0; sy < n; ++sy) {
          for (int sx = 0; sx < n; ++sx, h += 3) {
            // Pixel (col, row) covers [col - 0.5, col + 0.5] x [row - 0.5, row + 0.5].
            const double u = col + (sx + 0.5) / n - 0.5, v = static_cast<double>(row) + (sy + 0.5) / n - 0.5;
            const Eigen::Vector3d hit = Trace(cam.position_mm, PixelRayInWorld(cam, u, v));
            h[0] = static_cast<float>(hit.x());
            h[1] = static_cast<float>(hit.y());
            h[2] = static_cast<float>(hit.z());
          }
        }
        if (options_.vignetting) vignetting_[pixel] = static_cast<float>(Vignetting(cam, col, static_cast<double>(row)));
      }
    }
  });
}

Eigen::Vector3d SceneRenderer::HitPoint(int col, int row) const {
  const RigCamera& cam = rig_.cameras.at(camera_index_);
  const std::size_t pixel = static_cast<std::size_t>(row) * cam.width + col;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (int k = 0; k < rays_per_pixel_; ++k) {
    const float* h = &hits_.at((pixel * rays_per_pixel_ + k) * 3);
    sum += Eigen::Vector3d(h[0], h[1], h[2]);
  }
  return sum / rays_per_pixel_;
}

bool SceneRenderer::InShadow(const Eigen::Vector3d& p, const Eigen::Vector3d& l) const {
  if (!(l.z() > 0)) return true;  // a light below the sample plane lights nothing
  const double bias = options_.shadow_bias_pitch * scene_.pitch_mm;
  if (p.z() + bias >= max_height_mm_) return false;
  const double t_top = (max_height_mm_ - p.z()) / l.z();
  // Only the sample's box can block: clip the ray to it in x and y.
  double t_in = 0.0, t_out = t_top;
  const double lo[2] = {-half_width_mm_, -half_height_mm_}, hi[2] = {half_width_mm_, half_height_mm_};
  for (int a = 0; a < 2; ++a) {
    if (std::abs(l[a]) < 1e-15) {
      if (p[a] < lo[a] || p[a] > hi[a]) return false;
      continue;
    }
    double ta = (lo[a] - p[a]) / l[a], tb = (hi[a] - p[a]) / l[a];
    if (ta > tb) std::swap(ta, tb);
    t_in = std::max(t_in, ta);
    t_out = std::min(t_out, tb);
  }
  if (t_in >= t_out) return false;
  const SceneGrid grid(scene_);
  const double speed = std::hypot(l.x(), l.y());
  const double dt = std::min(t_top, options_.march_step_pitch * scene_.pitch_mm / std::max(speed, 1e-12));
  for (double t = std::max(t_in, dt); t <= t_out; t += dt) {
    const Eigen::Vector3d q = p + t * l;
    if (q.z() < grid.Height(q.x(), q.y()) - bias) return true;
  }
  return false;
}

// The pixel loop every front-lit image shares: each camera pixel averages shade_ray(hit, grid) over
// its rays (rays that miss everything add nothing), times exposure_scale * vignetting * ray_scale
// (in that order: the frames stay bit for bit what they were before this loop was shared).
template <typename ShadeRay>
Image SceneRenderer::AverageOverRays(float exposure_scale, float ray_scale, ShadeRay shade_ray) const {
  const RigCamera& cam = rig_.cameras[camera_index_];
  Image out(cam.width, cam.height, 3);
  const SceneGrid grid(scene_);
  float* planes[3] = {out.plane(0).data(), out.plane(1).data(), out.plane(2).data()};
  ParallelFor(cam.height, [&](std::size_t begin, std::size_t end) {
    for (std::size_t row = begin; row < end; ++row) {
      for (int col = 0; col < cam.width; ++col) {
        const std::size_t i = row * cam.width + col;
        Vec3<float> sum = Vec3<float>::Zero();
        for (int k = 0; k < rays_per_pixel_; ++k) {
          const float* h = &hits_[(i * rays_per_pixel_ + k) * 3];
          if (!std::isfinite(h[0])) continue;
          sum += shade_ray(Eigen::Vector3d(h[0], h[1], h[2]), grid);
        }
        const float scale = exposure_scale * vignetting_[i] * ray_scale;
        for (int c = 0; c < 3; ++c) planes[c][i] = scale * sum[c];
      }
    }
  });
  return out;
}

Image SceneRenderer::RenderLight(int light_index) const {
  if (camera_index_ < 0) throw std::logic_error("SceneRenderer::RenderLight before SetCamera");
  const RigCamera& cam = rig_.cameras[camera_index_];
  const RigLight& light = rig_.lights.at(light_index);
  const float table_brdf = static_cast<float>(rig_.table_reflectance / kPi);
  const float exposure = static_cast<float>(rig_.exposure_s);
  const float inv_rays = 1.0f / static_cast<float>(rays_per_pixel_);
  return AverageOverRays(exposure, inv_rays, [&](const Eigen::Vector3d& p, const SceneGrid& grid) -> Vec3<float> {
    Eigen::Vector3d l_world;
    const Eigen::Vector3d e = LightIrradiance(light, p, &l_world);
    if (options_.shadows && InShadow(p, l_world)) return Vec3<float>::Zero();
    const Vec3<float> l = ToVec3f(l_world);
    const Vec3<float> v = ToVec3f((cam.position_mm - p).normalized());
    Vec3<float> rgb = Vec3<float>::Zero();
    Footprint f;
    float alpha = 0.0f;
    if (grid.Locate(p.x(), p.y(), &f)) {
      const SurfacePoint sp = SampleSurface(scene_, f);
      alpha = sp.alpha;
      if (alpha > 0) {
        Vec3<float> t, b;
        LocalFrame(sp.normal, sp.tangent, &t, &b);
        const Vec3<float> l_local(l.dot(t), l.dot(b), l.dot(sp.normal));
        const Vec3<float> v_local(v.dot(t), v.dot(b), v.dot(sp.normal));
        rgb = alpha * std::max(0.0f, l_local.z()) * EvaluateModel(scene_.model, sp.params, l_local, v_local);
      }
    }
    if (alpha < 1) rgb += Vec3<float>::Constant((1 - alpha) * table_brdf * std::max(0.0f, l.z()));
    return rgb.cwiseProduct(ToVec3f(e));
  });
}

Image SceneRenderer::RenderAmbient() const {
  if (camera_index_ < 0) throw std::logic_error("SceneRenderer::RenderAmbient before SetCamera");
  // A uniform sky of irradiance E on a diffuse albedo a gives radiance a E / pi.
  const float scale = static_cast<float>(rig_.exposure_s * rig_.ambient_irradiance / kPi) / static_cast<float>(rays_per_pixel_);
  return AverageOverRays(scale, 1.0f, [&](const Eigen::Vector3d& p, const SceneGrid& grid) -> Vec3<float> {
    Vec3<float> albedo = Vec3<float>::Constant(static_cast<float>(rig_.table_reflectance));
    Footprint f;
    if (grid.Locate(p.x(), p.y(), &f)) {
      const SurfacePoint sp = SampleSurface(scene_, f);
      albedo = sp.alpha * sp.params.base_color * (1 - sp.params.metallic) + (1 - sp.alpha) * albedo;
    }
    return albedo;
  });
}

const Image& SceneRenderer::AmbientImage() {
  if (ambient_.empty()) ambient_ = RenderAmbient();
  return ambient_;
}

Image SceneRenderer::RenderBacklight(double level) const {
  if (camera_index_ < 0) throw std::logic_error("SceneRenderer::RenderBacklight before SetCamera");
  const RigCamera& cam = rig_.cameras[camera_index_];
  Image out(cam.width, cam.height, 1);
  const SceneGrid grid(scene_);
  const float scale = static_cast<float>(level) / static_cast<float>(rays_per_pixel_);
  ParallelFor(cam.height, [&](std::size_t begin, std::size_t end) {
    for (std::size_t row = begin; row < end; ++row) {
      for (int col = 0; col < cam.width; ++col) {
        const std::size_t i = row * cam.width + col;
        float transmitted = 0.0f;
        for (int k = 0; k < rays_per_pixel_; ++k) {
          const float* h = &hits_[(i * rays_per_pixel_ + k) * 3];
          if (!std::isfinite(h[0])) continue;
          Footprint f;
          float t = 1.0f;
          if (grid.Locate(h[0], h[1], &f)) t = 1.0f - std::clamp(SceneGrid::Sample(scene_.alpha, 0, f, 1.0f), 0.0f, 1.0f);
          transmitted += t;
        }
        out.plane(0)[i] = scale * vignetting_[i] * transmitted;
      }
    }
  });
  return out;
}

Image RenderPlaneTarget(const Rig& rig, int camera_index, const PlaneTarget& target, const RigLight* light,
                        bool with_ambient, int samples_per_axis, const RenderOptions& options) {
  CheckCamera(rig, camera_index);
  const RigCamera& cam = rig.cameras[camera_index];
  const Image& tex = target.albedo;
  if (tex.empty() || (tex.channels() != 1 && tex.channels() != 3)) throw std::invalid_argument("RenderPlaneTarget: texture");
  const double x0 = target.rect_mm[0], y0 = target.rect_mm[1], x1 = target.rect_mm[2], y1 = target.rect_mm[3];
  const int n = std::max(1, samples_per_axis);
  Image out(cam.width, cam.height, 3);
  const double ambient = with_ambient ? rig.ambient_irradiance : 0.0;
  ParallelFor(cam.height, [&](std::size_t begin, std::size_t end) {
    for (std::size_t row = begin; row < end; ++row) {
      for (int col = 0; col < cam.width; ++col) {
        Eigen::Vector3d sum = Eigen::Vector3d::Zero();
        ForEachSubRay(cam, col, static_cast<int>(row), n, [&](const Eigen::Vector3d& d) {
          if (!(d.z() < 0)) return;
          const Eigen::Vector3d p = cam.position_mm - (cam.position_mm.z() / d.z()) * d;
          Eigen::Vector3d albedo = Eigen::Vector3d::Constant(rig.table_reflectance);
          if (p.x() >= x0 && p.x() <= x1 && p.y() >= y0 && p.y() <= y1) {
            const double tc = std::clamp((p.x() - x0) / (x1 - x0) * tex.width() - 0.5, 0.0, tex.width() - 1.0);
            const double tr = std::clamp((y1 - p.y()) / (y1 - y0) * tex.height() - 0.5, 0.0, tex.height() - 1.0);
            const int c0 = std::min(static_cast<int>(tc), tex.width() - 1), r0 = std::min(static_cast<int>(tr), tex.height() - 1);
            const int c1 = std::min(c0 + 1, tex.width() - 1), r1 = std::min(r0 + 1, tex.height() - 1);
            const double fx = tc - c0, fy = tr - r0;
            for (int c = 0; c < 3; ++c) {
              const int ch = tex.channels() == 3 ? c : 0;
              albedo[c] = (1 - fy) * ((1 - fx) * tex.at(ch, r0, c0) + fx * tex.at(ch, r0, c1)) +
                          fy * ((1 - fx) * tex.at(ch, r1, c0) + fx * tex.at(ch, r1, c1));
            }
          }
          Eigen::Vector3d irradiance = Eigen::Vector3d::Constant(ambient);
          if (light != nullptr) {
            Eigen::Vector3d l;
            const Eigen::Vector3d e = LightIrradiance(*light, p, &l);
            irradiance += e * std::max(0.0, l.z());
          }
          sum += albedo.cwiseProduct(irradiance) / kPi;
        });
        const double vign = options.vignetting ? Vignetting(cam, col, static_cast<double>(row)) : 1.0;
        const double scale = rig.exposure_s * vign / (n * n);
        for (int c = 0; c < 3; ++c) out.at(c, static_cast<int>(row), col) = static_cast<float>(scale * sum[c]);
      }
    }
  });
  return out;
}

Image RenderMirrorSphere(const Rig& rig, int camera_index, const RigLight& light, const Eigen::Vector3d& center,
                         double radius_mm, double highlight_level, int samples_per_axis, const RenderOptions& options) {
  CheckCamera(rig, camera_index);
  const RigCamera& cam = rig.cameras[camera_index];
  const int n = std::max(1, samples_per_axis);
  // What the chrome mirrors of the dark room: the ambient light seen through a 60 % mirror.
  constexpr double kChromeReflectance = 0.6;
  const double room = kChromeReflectance * rig.exposure_s * rig.ambient_irradiance / kPi;
  // Nearest positive t where o + t d meets the sphere (c, r); -1 when it misses.
  auto hit_sphere = [](const Eigen::Vector3d& o, const Eigen::Vector3d& d, const Eigen::Vector3d& c, double r) {
    const Eigen::Vector3d oc = o - c;
    const double b = oc.dot(d);
    const double disc = b * b - (oc.squaredNorm() - r * r);
    if (disc <= 0) return -1.0;
    const double s = std::sqrt(disc);
    if (-b - s > 1e-9) return -b - s;
    if (-b + s > 1e-9) return -b + s;
    return -1.0;
  };
  Image out(cam.width, cam.height, 3);
  ParallelFor(cam.height, [&](std::size_t begin, std::size_t end) {
    for (std::size_t row = begin; row < end; ++row) {
      for (int col = 0; col < cam.width; ++col) {
        Eigen::Vector3d sum = Eigen::Vector3d::Zero();
        ForEachSubRay(cam, col, static_cast<int>(row), n, [&](const Eigen::Vector3d& d) {
          if (hit_sphere(cam.position_mm, d, center, radius_mm) > 0) {
            sum += Eigen::Vector3d::Constant(room);
            return;
          }
          if (!(d.z() < 0)) return;
          const Eigen::Vector3d p = cam.position_mm - (cam.position_mm.z() / d.z()) * d;
          Eigen::Vector3d l;
          const Eigen::Vector3d e = LightIrradiance(light, p, &l);
          const bool shadowed = hit_sphere(p, l, center, radius_mm) > 0;
          const double cos_i = shadowed ? 0.0 : std::max(0.0, l.z());
          sum += rig.exposure_s * rig.table_reflectance / kPi * (e * cos_i + Eigen::Vector3d::Constant(rig.ambient_irradiance));
        });
        const double vign = options.vignetting ? Vignetting(cam, col, static_cast<double>(row)) : 1.0;
        for (int c = 0; c < 3; ++c) out.at(c, static_cast<int>(row), col) = static_cast<float>(vign * sum[c] / (n * n));
      }
    }
  });

  // The mirrored emitter: a highlight of a few pixels at most, far smaller than a pixel for small
  // emitters, so it is drawn as what the lens makes of it: a Gaussian spot (peak highlight_level)
  // centred on the exact image of the reflection point, where the sphere normal bisects the
  // directions to the light and to the camera (fixed-point iteration; converges in a few steps).
  Eigen::Vector3d normal = (cam.position_mm - center).normalized();
  Eigen::Vector3d point = center + radius_mm * normal;
  for (int it = 0; it < 100; ++it) {
    const Eigen::Vector3d to_light =
        light.type == RigLightType::kDirectional ? light.direction : Eigen::Vector3d((light.position_mm - point).normalized());
    const Eigen::Vector3d next = (to_light + (cam.position_mm - point).normalized()).normalized();
    const double change = (next - normal).norm();
    normal = next;
    point = center + radius_mm * normal;
    if (change < 1e-13) break;
  }
  Eigen::Vector2d spot;
  if (!ProjectToPixel(cam, point, &spot)) return out;
  // Angular size of the emitter -> size of its image on the sphere (normal turns by half the angle).
  const double emitter_rad = light.type == RigLightType::kDirectional
                                 ? DegToRad(light.emitter_radius)
                                 : light.emitter_radius / (light.position_mm - point).norm();
  const double mm_per_px = (cam.position_mm - point).norm() / cam.fx;
  constexpr double kMinSpotSigmaPx = 1.0;  // a sharp lens's blur
  const double sigma = std::max(kMinSpotSigmaPx, 0.5 * radius_mm * 0.5 * emitter_rad / mm_per_px);
  const int reach = static_cast<int>(std::ceil(4 * sigma));
  const int c0 = std::max(0, static_cast<int>(spot.x()) - reach), c1 = std::min(cam.width - 1, static_cast<int>(spot.x()) + reach + 1);
  const int r0 = std::max(0, static_cast<int>(spot.y()) - reach), r1 = std::min(cam.height - 1, static_cast<int>(spot.y()) + reach + 1);
  for (int r = r0; r <= r1; ++r) {
    for (int c = c0; c <= c1; ++c) {
      const double d2 = (c - spot.x()) * (c - spot.x()) + (r - spot.y()) * (r - spot.y());
      const double value = highlight_level * std::exp(-0.5 * d2 / (sigma * sigma));
      for (int ch = 0; ch < 3; ++ch) out.at(ch, r, c) += static_cast<float>(value);
    }
  }
  return out;
}

}  // namespace u3mscan::synthetic
