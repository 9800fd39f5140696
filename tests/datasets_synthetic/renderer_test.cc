#include "datasets_synthetic/renderer.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

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

}  // namespace
}  // namespace u3mscan::synthetic
