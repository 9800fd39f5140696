#include "datasets_synthetic/renderer.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "core/parallel.h"
#include "core/principled_brdf.h"
#include "core/units.h"
#include "datasets_synthetic/rig.h"
#include "test_scenes.h"

namespace u3mscan::synthetic {
namespace {

using testing::FlatScene;
using testing::RidgeScene;

constexpr int kSize = 64;
constexpr int kSceneSize = 48;  // the sample covers the middle of the view, the table the rest
constexpr float kAlbedo = 0.6f;
// The table is exactly Lambertian: only float rounding separates render and formula.
constexpr double kTableRelativeTolerance = 1e-4;
// The sample has specular = 0, but Schlick's Fresnel still reflects SW(cos_d) <= 0.003 of the GGX
// lobe at these angles (under 0.5 % of the diffuse value); the formula below leaves it out.
constexpr double kSampleRelativeTolerance = 0.005;
// Pixels this close (mm) to the sample's edge blend sample and table bilinearly; skipped.
constexpr double kEdgeMarginPitches = 1.5;

// Irradiance computed here from the manifest's definitions, not through rig.cc.
Eigen::Vector3d AnalyticIrradiance(const RigLight& light, const Eigen::Vector3d& p, Eigen::Vector3d* l) {
  if (light.type == RigLightType::kDirectional) {
    *l = light.direction;
    return light.intensity_rgb;
  }
  const Eigen::Vector3d d = light.position_mm - p;
  *l = d.normalized();
  const double cos_axis = -l->dot(light.profile_axis);
  return light.intensity_rgb * std::pow(cos_axis, light.profile_exponent) / d.squaredNorm();
}

void ExpectFlatSceneMatchesAnalytic(const std::string& rig_name) {
  RigOptions rig_options;
  rig_options.width = rig_options.height = kSize;
  const Rig rig = MakeRig(rig_name, rig_options);
  const double pitch = rig.ground_pitch_mm;
  const SceneTruth scene = FlatScene(kSceneSize, kSceneSize, pitch, kAlbedo);
  SceneRenderer renderer(scene, rig);
  renderer.SetCamera(0);
  const RigCamera& cam = rig.cameras[0];
  const double half = 0.5 * kSceneSize * pitch;
  for (int light_index : {0, static_cast<int>(rig.lights.size()) - 1}) {
    const RigLight& light = rig.lights[light_index];
    const Image img = renderer.RenderLight(light_index);
    int table_pixels = 0, sample_pixels = 0;
    for (int row = 0; row < kSize; ++row) {
      for (int col = 0; col < kSize; ++col) {
        const Eigen::Vector3d p = renderer.HitPoint(col, row);
        ASSERT_NEAR(p.z(), 0.0, 1e-6);
        const double edge = std::max(std::abs(p.x()), std::abs(p.y())) - half;
        if (std::abs(edge) < kEdgeMarginPitches * pitch) continue;
        Eigen::Vector3d l;
        const Eigen::Vector3d e = AnalyticIrradiance(light, p, &l);
        const Eigen::Vector3d v = (cam.position_mm - p).normalized();
        const double scale = rig.exposure_s * Vignetting(cam, col, row) * l.z();
        const bool on_sample = edge < 0;
        double brdf;
        if (on_sample) {
          const double cos_d = l.dot((l + v).normalized());
          brdf = kAlbedo / kPi * brdf::DisneyDiffuse(l.z(), v.z(), cos_d, 0.5);
          ++sample_pixels;
        } else {
          brdf = rig.table_reflectance / kPi;
          ++table_pixels;
        }
        const double tol = on_sample ? kSampleRelativeTolerance : kTableRelativeTolerance;
        for (int c = 0; c < 3; ++c) {
          const double expected = scale * brdf * e[c];
          ASSERT_NEAR(img.at(c, row, col), expected, tol * expected) << rig_name << " light " << light_index << " px "
                                                                     << col << "," << row << " c" << c;
        }
      }
    }
    EXPECT_GT(table_pixels, 100);
    EXPECT_GT(sample_pixels, 1000);
  }
}

TEST(RendererTest, FlatLambertianMatchesAnalyticRadianceDirectional) { ExpectFlatSceneMatchesAnalytic("distant"); }

TEST(RendererTest, FlatLambertianMatchesAnalyticRadiancePointLights) { ExpectFlatSceneMatchesAnalytic("near"); }

TEST(RendererTest, ObliqueCameraSeesTheSampleCentre) {
  RigOptions options;
  options.width = options.height = kSize;
  const Rig rig = MakeRig("oblique", options);
  ASSERT_EQ(rig.cameras.size(), 2u);
  const RigCamera& cam = rig.cameras[1];
  const double tilt_deg = RadToDeg(std::acos(cam.position_mm.normalized().z()));
  EXPECT_GE(tilt_deg, 45.0);
  EXPECT_LE(tilt_deg, 75.0);
  Eigen::Vector2d px;
  ASSERT_TRUE(ProjectToPixel(cam, Eigen::Vector3d::Zero(), &px));
  EXPECT_NEAR(px.x(), cam.cx, 0.05 * kSize);
  EXPECT_NEAR(px.y(), cam.cy, 0.05 * kSize);
  // Undistortion inverts the projection's distortion.
  const Eigen::Vector3d corner(0.3 * kSize * options.pitch_mm, -0.2 * kSize * options.pitch_mm, 0.0);
  ASSERT_TRUE(ProjectToPixel(cam, corner, &px));
  const Eigen::Vector3d ray = PixelRayInWorld(cam, px.x(), px.y());
  const Eigen::Vector3d expected = (corner - cam.position_mm).normalized();
  EXPECT_LT((ray - expected).norm(), 1e-9);
}

// A wall of height h under a directional light from +x at elevation e shades the floor on its -x
// side over h / tan(e); the march and bilinear ramp put the edge within a pitch or two.
TEST(RendererTest, RidgeCastsShadowOfExpectedLength) {
  constexpr double kPitch = 0.05;
  constexpr int kWidth = 128, kHeight = 48, kSceneW = 96, kSceneH = 32, kRidge0 = 60, kRidge1 = 64;
  constexpr float kRidgeHeight = 0.5f;
  constexpr double kElevationDeg = 20.0;
  constexpr double kEdgeTolerancePitches = 2.0;
  RigOptions options;
  options.width = kWidth;
  options.height = kHeight;
  options.pitch_mm = kPitch;
  Rig rig = MakeRig("distant", options);
  rig.lights.resize(1);
  rig.lights[0].direction = Eigen::Vector3d(std::cos(DegToRad(kElevationDeg)), 0, std::sin(DegToRad(kElevationDeg)));
  const SceneTruth scene = RidgeScene(kSceneW, kSceneH, kPitch, kRidge0, kRidge1, kRidgeHeight);
  SceneRenderer renderer(scene, rig);
  renderer.SetCamera(0);
  const Image lit = renderer.RenderLight(0);
  RenderOptions no_shadows;
  no_shadows.shadows = false;
  SceneRenderer unshadowed_renderer(scene, rig, no_shadows);
  unshadowed_renderer.SetCamera(0);
  const Image unshadowed = unshadowed_renderer.RenderLight(0);

  // The top edge of the wall's lit-side face is at the centre of column kRidge0; the wall's
  // bilinear foot at the centre of column kRidge0 - 1.
  const double wall_top_x = (kRidge0 + 0.5 - 0.5 * kSceneW) * kPitch;
  const double foot_x = wall_top_x - kPitch;
  const double shadow_end_x = wall_top_x - kRidgeHeight / std::tan(DegToRad(kElevationDeg));
  int shadowed = 0, checked = 0;
  for (int row = kHeight / 2 - 4; row < kHeight / 2 + 4; ++row) {
    for (int col = 0; col < kWidth; ++col) {
      const Eigen::Vector3d p = renderer.HitPoint(col, row);
      if (std::abs(p.y()) > 0.4 * kSceneH * kPitch || p.z() > 1e-3) continue;  // floor near the middle only
      const bool is_shadowed = lit.at(1, row, col) < 0.5f * unshadowed.at(1, row, col);
      if (p.x() < foot_x && p.x() > shadow_end_x + kEdgeTolerancePitches * kPitch) {
        EXPECT_TRUE(is_shadowed) << "x = " << p.x();
        ++checked;
      }
      if (p.x() < shadow_end_x - kEdgeTolerancePitches * kPitch || p.x() > wall_top_x + kEdgeTolerancePitches * kPitch) {
        EXPECT_FALSE(is_shadowed) << "x = " << p.x();
        ++checked;
      }
      shadowed += is_shadowed;
    }
  }
  EXPECT_GT(checked, 200);
  EXPECT_GT(shadowed, 8 * 20);  // 8 rows of a ~27-pixel shadow
}

TEST(RendererTest, ClothMismatchChangesOnlySheenedScenes) {
  RigOptions options;
  options.width = options.height = 32;
  const Rig rig = MakeRig("near", options);
  SceneTruth scene = FlatScene(24, 24, rig.ground_pitch_mm, 0.4f);
  auto render = [&](ReflectanceModel model) {
    scene.model = model;
    SceneRenderer renderer(scene, rig);
    renderer.SetCamera(0);
    return renderer.RenderLight(0);
  };
  EXPECT_EQ(render(ReflectanceModel::kPrincipled).data(), render(ReflectanceModel::kClothMismatch).data());
  for (float& s : scene.sheen.plane(0)) s = 1.0f;
  const Image a = render(ReflectanceModel::kPrincipled), b = render(ReflectanceModel::kClothMismatch);
  double max_rel = 0;
  for (std::size_t i = 0; i < a.data().size(); ++i) {
    if (a.data()[i] > 0) max_rel = std::max(max_rel, std::abs(b.data()[i] - a.data()[i]) / static_cast<double>(a.data()[i]));
  }
  EXPECT_GT(max_rel, 0.01);
}

// Anisotropic highlights follow the scene's fibre direction; without a tangent map the fibres run
// along +x.
TEST(RendererTest, AnisotropyFollowsTheTangentMap) {
  RigOptions options;
  options.width = options.height = 32;
  const Rig rig = MakeRig("near", options);
  SceneTruth scene = FlatScene(32, 32, rig.ground_pitch_mm, 0.3f);
  for (float& v : scene.anisotropic.plane(0)) v = 0.9f;
  for (float& v : scene.roughness.plane(0)) v = 0.3f;
  for (float& v : scene.specular.plane(0)) v = 1.0f;
  auto render = [&](float tx, float ty) {
    if (tx == 0 && ty == 0) {
      scene.tangent = Image();
    } else {
      scene.tangent = Image(32, 32, 3, 0.0f, scene.pitch_mm);
      for (float& v : scene.tangent.plane(0)) v = tx;
      for (float& v : scene.tangent.plane(1)) v = ty;
    }
    SceneRenderer renderer(scene, rig);
    renderer.SetCamera(0);
    return renderer.RenderLight(8);
  };
  const Image none = render(0, 0), along_x = render(1, 0), along_y = render(0, 1);
  EXPECT_EQ(none.data(), along_x.data());
  double max_rel = 0;
  for (std::size_t i = 0; i < none.data().size(); ++i) {
    max_rel = std::max(max_rel, std::abs(along_y.data()[i] - none.data()[i]) / static_cast<double>(none.data()[i]));
  }
  EXPECT_GT(max_rel, 0.05);
}

TEST(RendererTest, BacklightPassesThroughHolesOnly) {
  RigOptions options;
  options.width = options.height = 32;
  const Rig rig = MakeRig("distant", options);
  SceneTruth scene = FlatScene(32, 32, rig.ground_pitch_mm, 0.5f);
  for (int r = 12; r < 20; ++r)
    for (int c = 12; c < 20; ++c) scene.alpha.at(0, r, c) = 0.0f;
  SceneRenderer renderer(scene, rig);
  renderer.SetCamera(0);
  const Image back = renderer.RenderBacklight(0.7);
  const Eigen::Vector3d centre_hit = renderer.HitPoint(16, 16);
  ASSERT_LT(centre_hit.head<2>().norm(), 2 * rig.ground_pitch_mm);
  EXPECT_NEAR(back.at(0, 16, 16), 0.7, 0.01);
  EXPECT_NEAR(back.at(0, 4, 4), 0.0, 1e-6);
}

TEST(RendererTest, UnknownRigNameThrows) {
  EXPECT_THROW(MakeRig("nonesuch", RigOptions{}), std::invalid_argument);
  for (const std::string& name : RigNames()) {
    const Rig rig = MakeRig(name, RigOptions{});
    EXPECT_GE(rig.lights.size(), 8u) << name;
    EXPECT_LE(rig.lights.size(), 32u) << name;
  }
}

// ---- Supersampling: a camera pixel integrates over its area, the truth is the area average. ----

constexpr int kAreaCamera = 64;       // camera pixels a side
constexpr int kAreaScene = 48;        // output-grid pixels a side (kAreaCamera - kAreaScene even)
constexpr int kAreaFactor = 3;        // fine scene and rays per pixel axis
constexpr double kAreaPeriodPx = 6.0;  // albedo sinusoid period in output pixels
constexpr float kAreaMean = 0.5f, kAreaAmplitude = 0.2f;

// A flat diffuse sample (specular 0) whose albedo is kAreaMean + kAreaAmplitude (sin(k x) + sin(k y))
// / 2, sampled on the grid of `options` (pattern position origin + col pitch, origin - row pitch).
SceneTruth SinusoidAlbedoScene(const SceneOptions& options, double coarse_pitch_mm) {
  SceneTruth s = FlatScene(options.width, options.height, options.pitch_mm, kAreaMean);
  const double k = 2.0 * kPi / (kAreaPeriodPx * coarse_pitch_mm);
  for (int r = 0; r < options.height; ++r) {
    for (int c = 0; c < options.width; ++c) {
      const double x = options.origin_x_mm + c * options.pitch_mm, y = options.origin_y_mm - r * options.pitch_mm;
      const double a = kAreaMean + 0.5 * kAreaAmplitude * (std::sin(k * x) + std::sin(k * y));
      for (int ch = 0; ch < 3; ++ch) s.base_color.at(ch, r, c) = static_cast<float>(a);
    }
  }
  return s;
}

// The distant rig's top camera without lens distortion, with square pixels, its principal point `offset_px` off the
// centre: 0 puts every camera pixel exactly on an output-grid pixel, 0.5 half-way between four.
Rig AreaTestRig(double offset_px) {
  RigOptions options;
  options.width = options.height = kAreaCamera;
  Rig rig = MakeRig("distant", options);
  RigCamera& cam = rig.cameras[0];
  cam.distortion.fill(0.0);
  cam.fy = cam.fx;  // square pixels on the plane (the rig jitters fy by 0.1 %)
  cam.cx = 0.5 * (kAreaCamera - 1) + offset_px;
  cam.cy = 0.5 * (kAreaCamera - 1) + offset_px;
  return rig;
}

// Render of `scene` under light 0 divided by the render of a white flat scene on the same grid:
// the effective albedo each camera pixel sees (light, view, vignetting and cosine cancel).
Image SeenAlbedo(const SceneTruth& scene, const Rig& rig, int supersample) {
  RenderOptions options;
  options.supersample = supersample;
  SceneTruth white = FlatScene(scene.height_mm.width(), scene.height_mm.height(), scene.pitch_mm, 1.0f);
  SceneRenderer a(scene, rig, options), b(white, rig, options);
  a.SetCamera(0);
  b.SetCamera(0);
  Image img = a.RenderLight(0);
  const Image ref = b.RenderLight(0);
  for (std::size_t i = 0; i < img.data().size(); ++i) img.data()[i] /= ref.data()[i];
  return img;
}

// Standard deviation of channel 0 over the centred n x n crop.
double CentreStd(const Image& image, int n) {
  const int c0 = (image.width() - n) / 2, r0 = (image.height() - n) / 2;
  double s = 0, s2 = 0;
  for (int r = r0; r < r0 + n; ++r)
    for (int c = c0; c < c0 + n; ++c) s += image.at(0, r, c), s2 += image.at(0, r, c) * image.at(0, r, c);
  const double m = s / (n * n);
  return std::sqrt(std::max(0.0, s2 / (n * n) - m * m));
}

SceneOptions AreaGrid(double pitch_mm) {
  SceneOptions o;
  o.width = o.height = kAreaScene;
  o.pitch_mm = pitch_mm;
  return o;
}

// With camera pixels exactly on the output grid, the supersampled render of the fine scene is the
// render of its area-average truth: what the sensor integrates is what the truth holds.
TEST(RendererAreaTest, AlignedCameraSeesTheAreaAverageTruth) {
  // Both sides are linear in the albedo; only float rounding of ray hits and sums differs.
  constexpr double kAlignedTolerance = 2e-5;
  const Rig rig = AreaTestRig(0.0);
  const SceneOptions grid = AreaGrid(rig.ground_pitch_mm);
  const SceneTruth fine = SinusoidAlbedoScene(OversampledSceneOptions(grid, kAreaFactor), grid.pitch_mm);
  const SceneTruth truth = AreaAverageScene(fine, kAreaFactor);
  const Image seen = SeenAlbedo(fine, rig, kAreaFactor);
  const int offset = (kAreaCamera - kAreaScene) / 2;
  double max_error = 0, truth_range = 0;
  for (int r = 1; r + 1 < kAreaScene; ++r) {
    for (int c = 1; c + 1 < kAreaScene; ++c) {
      const double expected = truth.base_color.at(0, r, c);
      max_error = std::max(max_error, std::abs(seen.at(0, r + offset, c + offset) - expected));
      truth_range = std::max(truth_range, std::abs(expected - kAreaMean));
    }
  }
  EXPECT_LT(max_error, kAlignedTolerance);
  EXPECT_GT(truth_range, 0.5 * kAreaAmplitude);  // the pattern is there to be seen
}

// Half a pixel off the grid, the camera sees other pixel footprints than the truth holds, but a
// box filter keeps a smooth pattern's contrast whatever its phase. One ray per pixel on the
// point-sampled grid (the renderer before supersampling) interpolates bilinearly half-way between
// samples and loses a sixth of it at this period.
TEST(RendererAreaTest, OffGridCameraKeepsTheContrastOfTheTruth) {
  // Left: the fine scene's bilinear steps (a third of a pixel) and the 3-point midpoint rule, ~1.5 %.
  constexpr double kContrastTolerance = 0.025;
  // The single-ray render: cos(pi / 6) = 0.87 per axis for a half-pixel bilinear shift.
  constexpr double kBlurredBelow = 0.92;
  constexpr int kCrop = 36;  // six whole periods: the std does not depend on the phase
  const Rig rig = AreaTestRig(0.5);
  const SceneOptions grid = AreaGrid(rig.ground_pitch_mm);
  const SceneTruth fine = SinusoidAlbedoScene(OversampledSceneOptions(grid, kAreaFactor), grid.pitch_mm);
  const SceneTruth truth = AreaAverageScene(fine, kAreaFactor);
  const double truth_std = CentreStd(truth.base_color, kCrop);
  const double ratio = CentreStd(SeenAlbedo(fine, rig, kAreaFactor), kCrop) / truth_std;
  EXPECT_NEAR(ratio, 1.0, kContrastTolerance);
  const SceneTruth point = SinusoidAlbedoScene(grid, grid.pitch_mm);
  const double point_ratio = CentreStd(SeenAlbedo(point, rig, 1), kCrop) / CentreStd(point.base_color, kCrop);
  EXPECT_LT(point_ratio, kBlurredBelow);
}

TEST(RendererAreaTest, SupersampledRenderIsIndependentOfTheThreadCount) {
  RigOptions options;
  options.width = options.height = 32;
  const Rig rig = MakeRig("near", options);
  SceneOptions grid = AreaGrid(rig.ground_pitch_mm);
  grid.width = grid.height = 24;
  const SceneTruth scene = MakeScene("twill", OversampledSceneOptions(grid, 2));
  RenderOptions render;
  render.supersample = 2;
  const int threads = GetThreadCount();
  auto run = [&](int n) {
    SetThreadCount(n);
    SceneRenderer r(scene, rig, render);
    r.SetCamera(0);
    return r.RenderLight(3);
  };
  const Image one = run(1), many = run(4);
  SetThreadCount(threads);
  EXPECT_EQ(one.data(), many.data());
}

}  // namespace
}  // namespace u3mscan::synthetic
