#pragma once
// The renderer of the synthetic scanner: what each camera of a rig sees of a scene under each
// light, as the linear value a decoder would return (docs/capture-format.md, "Grids and
// radiometry"): exposure_s * f(wi, wo) * cos(theta_i) * E, times the lens vignetting. No noise
// and no quantisation here; sensor.h adds those.
//
// The sample (SceneTruth) lies centred on the world origin in z = 0: its pixel (col, row) centre is
// at x = (col + 0.5 - W/2) pitch, y = (H/2 - row - 0.5) pitch, z = height_mm. Outside it, a
// Lambertian table of Rig::table_reflectance at z = 0. A camera pixel integrates light over its
// area: it casts supersample x supersample rays through a regular grid of points of its footprint
// (exact undistortion per ray), each marches the height field (bilinear between the scene's
// samples) and refines the hit by bisection; the pixel is the mean (a box filter) of the rays'
// shading. Each ray is shaded with
// the Principled BRDF of core/principled_brdf.h in the surface's local frame (z = normal, x = the
// scene's tangent map, the fibre direction and axis of anisotropy, or +x projected onto the
// tangent plane when the scene has none). Cast shadows: a march from the
// hit toward the light. Holes (alpha < 1) blend the fabric with the table below.

#include <Eigen/Core>
#include <vector>

#include "core/image.h"
#include "core/principled_brdf.h"
#include "datasets_synthetic/rig.h"
#include "datasets_synthetic/scene.h"

namespace u3mscan::synthetic {

struct RenderOptions {
  bool shadows = true;
  bool vignetting = true;
  // The hit must be this far below the height field for a shadow ray to count as blocked (mm,
  // relative to the scene pitch): absorbs the bilinear surface's curvature at the start point.
  double shadow_bias_pitch = 0.01;
  // Ray-march step along the sample plane, in scene pixels; bisection refines the crossing.
  double march_step_pitch = 0.5;
  // Rays per camera pixel along each axis, at the centres of an n x n split of the pixel: the
  // pixel's value is their mean (a box filter over its area, as a sensor integrates). 1 = one ray
  // through the pixel centre. Memory: 12 bytes per ray for the cached hits of one camera.
  int supersample = 1;
};

// Renders one scene with one rig. Construct once, then SetCamera (traces that camera's rays once)
// and render any number of lights. Not thread-safe per instance; parallel over rows inside.
class SceneRenderer {
 public:
  SceneRenderer(const SceneTruth& scene, const Rig& rig, RenderOptions options = {});

  void SetCamera(int camera_index);
  int camera_index() const { return camera_index_; }

  // 3 channels, the camera's size: one light, no ambient.
  Image RenderLight(int light_index) const;
  // 3 channels: the room light alone, a uniform sky of Rig::ambient_irradiance (no occlusion).
  Image RenderAmbient() const;
  // RenderAmbient of the current camera, computed once and kept until the next SetCamera (every
  // sample frame carries the room light).
  const Image& AmbientImage();
  // 1 channel: a light table of apparent value `level` behind the sample, front lights off. Where
  // the camera sees the sample, (1 - alpha) of it comes through; around the sample, all of it.
  Image RenderBacklight(double level) const;

  // Surface point the rays of pixel (col, row) hit (world, mm), the mean of its rays' hits (the
  // centre ray's hit when supersample = 1); valid after SetCamera.
  Eigen::Vector3d HitPoint(int col, int row) const;
  // True when the height field blocks the way from `point_mm` toward the light.
  bool InShadow(const Eigen::Vector3d& point_mm, const Eigen::Vector3d& direction_to_light) const;
  // Height of the sample (mm) at world (x, y); 0 on the table.
  double HeightAt(double x_mm, double y_mm) const;

 private:
  // The pixel loop of RenderLight and RenderAmbient; ShadeRay(hit point mm, scene grid) -> RGB.
  template <typename ShadeRay>
  Image AverageOverRays(float exposure_scale, float ray_scale, ShadeRay shade_ray) const;
  Eigen::Vector3d Trace(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction) const;

  const SceneTruth& scene_;
  const Rig& rig_;
  RenderOptions options_;
  int camera_index_ = -1;
  double half_width_mm_ = 0, half_height_mm_ = 0;
  double min_height_mm_ = 0, max_height_mm_ = 0;
  int rays_per_pixel_ = 1;       // supersample^2
  std::vector<float> hits_;      // x, y, z per ray; a pixel's rays are consecutive; NaN: no hit
  std::vector<float> vignetting_;  // per camera pixel, at its centre
  Image ambient_;            // AmbientImage() cache, empty until asked
};

// A flat Lambertian target lying in z = 0 (white target, ChArUco board, colour chart): `albedo` is a
// 1- or 3-channel texture whose texel (0, 0) is the top-left corner of rect_mm = [x0, y0, x1, y1]
// (rows go toward -y); outside the rectangle the table of the rig.
struct PlaneTarget {
  Image albedo;
  double rect_mm[4] = {0, 0, 0, 0};
};

// Renders the target as camera `camera_index` sees it under `light` (nullptr: dark) plus the rig's
// ambient light when `with_ambient`; `samples_per_axis`^2 rays per pixel (box filter) so that
// edges of printed targets are anti-aliased as a real lens and sensor would.
Image RenderPlaneTarget(const Rig& rig, int camera_index, const PlaneTarget& target, const RigLight* light,
                        bool with_ambient, int samples_per_axis, const RenderOptions& options = {});

// A chrome sphere of `radius_mm` centred at `center_mm` (resting on z = 0 when center z = radius)
// under one light. The sphere mirrors a dark room (the ambient light); the table around it is lit
// by the light and shadowed by the sphere. The mirrored emitter is a Gaussian spot of peak
// `highlight_level` centred exactly on the image of the reflection point (where the sphere normal
// bisects the directions to light and camera), sigma from the emitter's angular size, at least
// 1 px: a highlight much smaller than a pixel, as a lens would blur it, with an unbiased centroid.
// Supersampled like RenderPlaneTarget.
Image RenderMirrorSphere(const Rig& rig, int camera_index, const RigLight& light, const Eigen::Vector3d& center_mm,
                         double radius_mm, double highlight_level, int samples_per_axis,
                         const RenderOptions& options = {});

// f (1/sr) of the model a scene asks for; L, V unit in the local frame (z = normal). kPrincipled is
// core's EvaluatePrincipled; kClothMismatch replaces Disney's sheen by the Estevez-Kulla "Charlie"
// sheen (SIGGRAPH 2017) with the Neubelt-Pettineo visibility, a lobe the fitter does not model.
Vec3<float> EvaluateModel(ReflectanceModel model, const PrincipledParams<float>& params, const Vec3<float>& l,
                          const Vec3<float>& v);

}  // namespace u3mscan::synthetic
