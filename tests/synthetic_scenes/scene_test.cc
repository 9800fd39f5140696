// Scene presets: value ranges, normals, determinism, holes, physical scale, closed-form normals.

#include "datasets_synthetic/scene.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <set>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "core/parallel.h"
#include "datasets_synthetic/scene_analytic.h"

namespace u3mscan::synthetic {
namespace {

constexpr int kSize = 64;
constexpr double kPitchMm = 25.4 / 300.0;
// Normals are recomputed here in double from the same float heights as the scene's.
constexpr double kNormalRecomputeTolerance = 1e-5;
constexpr double kUnitLengthTolerance = 1e-5;
// Central differences vs the closed form at 300 dpi: the slope error of a cosine of period L is
// (2 pi pitch / L)^2 / 6 = 1.2 % of a slope <= 0.47, i.e. < 0.006 per normal component.
constexpr double kCentralDifferenceTolerance = 0.01;
// Heights of a 2x-dpi grid equal the coarse grid's at the shared points (same x, y in double).
constexpr float kSameSampleTolerance = 1e-6f;

// Presets whose maps do not depend on the seed (closed-form geometry, one constant material).
const std::set<std::string> kSeedless = {"flat_lambertian", "sphere_cap", "bumps", "velvet_bumps"};
const std::set<std::string> kFabrics = {"plain", "twill", "satin", "knit", "denim", "velvet", "lace"};

SceneOptions Options(std::uint64_t seed = 7, int size = kSize, double pitch_mm = kPitchMm) {
  SceneOptions o;
  o.width = size;
  o.height = size;
  o.pitch_mm = pitch_mm;
  o.seed = seed;
  return o;
}

std::vector<const Image*> ParameterMaps(const SceneTruth& t) {
  return {&t.base_color, &t.roughness, &t.specular, &t.specular_tint, &t.sheen, &t.sheen_tint,
          &t.metallic,   &t.anisotropic, &t.alpha};
}

std::vector<const Image*> AllMaps(const SceneTruth& t) {
  auto maps = ParameterMaps(t);
  maps.push_back(&t.height_mm);
  maps.push_back(&t.normal);
  maps.push_back(&t.tangent);
  return maps;
}

TEST(SceneNamesTest, HoldsTheIssuePresetsAndTheExtremeOnes) {
  const auto names = SceneNames();
  for (const char* required : {"plain", "twill", "satin", "knit", "denim", "velvet", "lace", "dark", "bright",
                               "mirror", "pure_velvet", "holes", "flat_lambertian", "sphere_cap", "bumps",
                               "velvet_bumps", "velvet_mismatch"}) {
    EXPECT_NE(std::find(names.begin(), names.end(), required), names.end()) << required;
  }
}

TEST(MakeSceneTest, RejectsUnknownNamesAndBadOptions) {
  EXPECT_THROW(MakeScene("tweed_unknown", Options()), std::invalid_argument);
  SceneOptions bad = Options();
  bad.pitch_mm = 0.0;
  EXPECT_THROW(MakeScene("plain", bad), std::invalid_argument);
  bad = Options();
  bad.width = 0;
  EXPECT_THROW(MakeScene("plain", bad), std::invalid_argument);
}

class EveryScene : public ::testing::TestWithParam<std::string> {};

TEST_P(EveryScene, MapsHaveTheGridAndFiniteValuesInRange) {
  const SceneTruth t = MakeScene(GetParam(), Options());
  EXPECT_EQ(t.name, GetParam());
  EXPECT_DOUBLE_EQ(t.pitch_mm, kPitchMm);
  for (const Image* image : AllMaps(t)) {
    ASSERT_EQ(image->width(), kSize);
    ASSERT_EQ(image->height(), kSize);
    EXPECT_DOUBLE_EQ(image->pitch_mm(), kPitchMm);
    for (float v : image->data()) ASSERT_TRUE(std::isfinite(v));
  }
  for (const Image* image : ParameterMaps(t)) {
    for (float v : image->data()) {
      ASSERT_GE(v, 0.0f);
      ASSERT_LE(v, 1.0f);
    }
  }
  for (float m : t.metallic.data()) ASSERT_EQ(m, 0.0f);  // fabric is a dielectric
  EXPECT_LE(t.height_min_mm, t.height_max_mm);
  for (float h : t.height_mm.data()) {
    ASSERT_GE(h, t.height_min_mm);
    ASSERT_LE(h, t.height_max_mm);
  }
}

TEST_P(EveryScene, NormalsAreUnitAndTheHeightGradient) {
  const SceneTruth t = MakeScene(GetParam(), Options());
  const double p = t.pitch_mm;
  for (int r = 0; r < kSize; ++r) {
    for (int c = 0; c < kSize; ++c) {
      const double nx = t.normal.at(0, r, c), ny = t.normal.at(1, r, c), nz = t.normal.at(2, r, c);
      ASSERT_NEAR(nx * nx + ny * ny + nz * nz, 1.0, kUnitLengthTolerance);
      ASSERT_GT(nz, 0.0);
      if (r == 0 || c == 0 || r == kSize - 1 || c == kSize - 1) continue;
      // x right, y up: the row above (r - 1) is +y.
      const double gx = (t.height_mm.at(0, r, c + 1) - t.height_mm.at(0, r, c - 1)) / (2 * p);
      const double gy = (t.height_mm.at(0, r - 1, c) - t.height_mm.at(0, r + 1, c)) / (2 * p);
      const double len = std::sqrt(gx * gx + gy * gy + 1.0);
      ASSERT_NEAR(nx, -gx / len, kNormalRecomputeTolerance) << r << "," << c;
      ASSERT_NEAR(ny, -gy / len, kNormalRecomputeTolerance) << r << "," << c;
      ASSERT_NEAR(nz, 1.0 / len, kNormalRecomputeTolerance) << r << "," << c;
    }
  }
}

TEST_P(EveryScene, TangentsAreUnitAndOrthogonalToTheNormal) {
  const SceneTruth t = MakeScene(GetParam(), Options());
  for (int r = 0; r < kSize; ++r) {
    for (int c = 0; c < kSize; ++c) {
      double len2 = 0.0, dot = 0.0;
      for (int k = 0; k < 3; ++k) {
        len2 += t.tangent.at(k, r, c) * t.tangent.at(k, r, c);
        dot += t.tangent.at(k, r, c) * t.normal.at(k, r, c);
      }
      ASSERT_NEAR(len2, 1.0, kUnitLengthTolerance);
      ASSERT_NEAR(dot, 0.0, kUnitLengthTolerance);
    }
  }
}

TEST_P(EveryScene, SameSeedGivesIdenticalMapsForAnyThreadCount) {
  const int threads = GetThreadCount();
  SetThreadCount(1);
  const SceneTruth a = MakeScene(GetParam(), Options(11));
  SetThreadCount(3);
  const SceneTruth b = MakeScene(GetParam(), Options(11));
  SetThreadCount(threads);
  const auto ma = AllMaps(a), mb = AllMaps(b);
  for (std::size_t i = 0; i < ma.size(); ++i) EXPECT_EQ(ma[i]->data(), mb[i]->data()) << "map " << i;
}

TEST_P(EveryScene, DifferentSeedGivesDifferentMaps) {
  if (kSeedless.count(GetParam())) GTEST_SKIP() << "closed-form preset, no random part";
  const SceneTruth a = MakeScene(GetParam(), Options(1));
  const SceneTruth b = MakeScene(GetParam(), Options(2));
  EXPECT_NE(a.height_mm.data(), b.height_mm.data());
  if (GetParam() != "dark" && GetParam() != "bright" && GetParam() != "mirror" && GetParam() != "pure_velvet") {
    EXPECT_NE(a.base_color.data(), b.base_color.data());  // per-thread colour variation
  }
}

TEST_P(EveryScene, TwiceTheDpiSamplesTheSamePhysicalPattern) {
  if (GetParam() == "sphere_cap") GTEST_SKIP() << "the cap is sized to the grid by design";
  const SceneTruth coarse = MakeScene(GetParam(), Options(5, kSize, kPitchMm));
  const SceneTruth fine = MakeScene(GetParam(), Options(5, 2 * kSize, kPitchMm / 2));
  for (int r = 0; r < kSize; ++r) {
    for (int c = 0; c < kSize; ++c) {
      ASSERT_NEAR(fine.height_mm.at(0, 2 * r, 2 * c), coarse.height_mm.at(0, r, c), kSameSampleTolerance);
      ASSERT_EQ(fine.alpha.at(0, 2 * r, 2 * c), coarse.alpha.at(0, r, c));
      for (int k = 0; k < 3; ++k) {
        ASSERT_NEAR(fine.base_color.at(k, 2 * r, 2 * c), coarse.base_color.at(k, r, c), kSameSampleTolerance);
      }
    }
  }
}

// A 3x finer grid from OversampledSceneOptions tiles each coarse pixel with 3 x 3 fine pixels;
// the middle one is centred on the coarse pixel's point sample.
TEST_P(EveryScene, OversampledGridTilesTheCoarsePixels) {
  constexpr int kCoarse = 16, kFactor = 3;
  const SceneOptions coarse_options = Options(5, kCoarse, kPitchMm);
  const SceneTruth coarse = MakeScene(GetParam(), coarse_options);
  const SceneTruth fine = MakeScene(GetParam(), OversampledSceneOptions(coarse_options, kFactor));
  ASSERT_EQ(fine.height_mm.width(), kFactor * kCoarse);
  ASSERT_DOUBLE_EQ(fine.pitch_mm * kFactor, kPitchMm);
  // From 1: x = 0 and y = 0 are thread boundaries of the weaves, where the fine grid's -p/3 + p/3
  // (1e-18 mm off zero) rightly picks the other thread.
  for (int r = 1; r < kCoarse; ++r) {
    for (int c = 1; c < kCoarse; ++c) {
      const int fr = kFactor * r + 1, fc = kFactor * c + 1;
      ASSERT_NEAR(fine.height_mm.at(0, fr, fc), coarse.height_mm.at(0, r, c), kSameSampleTolerance) << r << "," << c;
      ASSERT_EQ(fine.alpha.at(0, fr, fc), coarse.alpha.at(0, r, c));
      for (int k = 0; k < 3; ++k) {
        ASSERT_NEAR(fine.base_color.at(k, fr, fc), coarse.base_color.at(k, r, c), kSameSampleTolerance) << r << "," << c;
      }
    }
  }
}

TEST_P(EveryScene, AreaAverageHasUnitNormalsAndTangentsAndKeepsTheMeans) {
  constexpr int kCoarse = 12, kFactor = 3;
  // Means of float maps summed in double in a different order.
  constexpr double kMeanTolerance = 1e-5;
  const SceneOptions coarse_options = Options(5, kCoarse, kPitchMm);
  const SceneTruth fine = MakeScene(GetParam(), OversampledSceneOptions(coarse_options, kFactor));
  const SceneTruth t = AreaAverageScene(fine, kFactor);
  ASSERT_EQ(t.height_mm.width(), kCoarse);
  EXPECT_DOUBLE_EQ(t.pitch_mm, kPitchMm);
  for (int r = 0; r < kCoarse; ++r) {
    for (int c = 0; c < kCoarse; ++c) {
      double nn = 0, tt = 0, nt = 0;
      for (int k = 0; k < 3; ++k) {
        nn += t.normal.at(k, r, c) * t.normal.at(k, r, c);
        tt += t.tangent.at(k, r, c) * t.tangent.at(k, r, c);
        nt += t.normal.at(k, r, c) * t.tangent.at(k, r, c);
      }
      ASSERT_NEAR(nn, 1.0, kUnitLengthTolerance);
      ASSERT_NEAR(tt, 1.0, kUnitLengthTolerance);
      ASSERT_NEAR(nt, 0.0, kUnitLengthTolerance);
    }
  }
  EXPECT_NEAR(t.height_mm.ChannelMean(0), fine.height_mm.ChannelMean(0), kMeanTolerance);
  EXPECT_NEAR(t.alpha.ChannelMean(0), fine.alpha.ChannelMean(0), kMeanTolerance);
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(t.base_color.ChannelMean(k), fine.base_color.ChannelMean(k), kMeanTolerance);
}

TEST_P(EveryScene, TinyAndNonSquareGridsWork) {
  // Border normals come from the model beyond the grid, so even a single pixel has one.
  for (const auto& [w, h] : {std::pair{1, 1}, std::pair{3, 2}, std::pair{17, 5}}) {
    SceneOptions o = Options();
    o.width = w;
    o.height = h;
    const SceneTruth t = MakeScene(GetParam(), o);
    ASSERT_EQ(t.normal.width(), w);
    ASSERT_EQ(t.normal.height(), h);
    for (float v : t.normal.data()) ASSERT_TRUE(std::isfinite(v));
    for (int r = 0; r < h; ++r) {
      for (int c = 0; c < w; ++c) ASSERT_GT(t.normal.at(2, r, c), 0.0f);
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Presets, EveryScene, ::testing::ValuesIn(SceneNames()),
                         [](const auto& info) { return info.param; });

double AlphaMean(const SceneTruth& t) { return t.alpha.ChannelMean(0); }

TEST(ScenePresetsTest, LaceAndOpenWeaveHaveHolesDenseWeavesNone) {
  EXPECT_LT(AlphaMean(MakeScene("lace", Options())), 0.9);
  EXPECT_LT(AlphaMean(MakeScene("holes", Options())), 0.85);  // many holes: ~25 % by construction
  for (const char* dense : {"plain", "twill", "satin", "denim", "knit", "velvet"}) {
    EXPECT_EQ(AlphaMean(MakeScene(dense, Options())), 1.0) << dense;
  }
}

TEST(ScenePresetsTest, FabricsHaveRealisticRelief) {
  // Issue 3: threads 0.1-1 mm, heights 0.05-1 mm.
  for (const std::string& name : kFabrics) {
    const SceneTruth t = MakeScene(name, Options(3, 128));
    const auto [lo, hi] = std::minmax_element(t.height_mm.data().begin(), t.height_mm.data().end());
    EXPECT_GE(*hi - *lo, 0.05) << name;
    EXPECT_LE(t.height_max_mm - t.height_min_mm, 1.0) << name;
    ASSERT_FALSE(t.yarns.empty()) << name;
    for (const YarnTruth& y : t.yarns) {
      EXPECT_GE(y.width_mm, 0.1) << name << " " << y.name;
      EXPECT_LE(y.width_mm, 1.0) << name << " " << y.name;
      EXPECT_EQ(y.metallic, 0.0f);
    }
  }
}

TEST(ScenePresetsTest, MaterialsFollowTheirFabric) {
  const SceneTruth plain = MakeScene("plain", Options());
  const SceneTruth satin = MakeScene("satin", Options());
  const SceneTruth velvet = MakeScene("velvet", Options());
  const SceneTruth denim = MakeScene("denim", Options());
  EXPECT_LT(satin.roughness.ChannelMean(0), plain.roughness.ChannelMean(0) - 0.3);
  EXPECT_GT(satin.anisotropic.ChannelMean(0), 0.5);
  EXPECT_GT(velvet.sheen.ChannelMean(0), 0.8);
  EXPECT_GT(plain.roughness.ChannelMean(0), 0.6);
  // Denim: blue warp and white weft both visible.
  int blue = 0, white = 0;
  for (int r = 0; r < kSize; ++r) {
    for (int c = 0; c < kSize; ++c) {
      const float red = denim.base_color.at(0, r, c), b = denim.base_color.at(2, r, c);
      if (b > 2.0f * red) ++blue;
      if (red > 0.5f) ++white;
    }
  }
  EXPECT_GT(blue, kSize * kSize / 2);  // 3/1 warp-faced
  EXPECT_GT(white, kSize * kSize / 20);
  EXPECT_EQ(velvet.model, ReflectanceModel::kPrincipled);
  EXPECT_EQ(MakeScene("velvet_mismatch", Options()).model, ReflectanceModel::kClothMismatch);
}

TEST(ScenePresetsTest, ExtremePresetsHoldTheirExtremes) {
  const SceneTruth dark = MakeScene("dark", Options());
  for (float v : dark.base_color.data()) ASSERT_FLOAT_EQ(v, 0.01f);
  const SceneTruth bright = MakeScene("bright", Options());
  for (float v : bright.base_color.data()) ASSERT_FLOAT_EQ(v, 1.0f);
  const SceneTruth mirror = MakeScene("mirror", Options());
  for (float v : mirror.roughness.data()) ASSERT_FLOAT_EQ(v, 0.02f);
  const SceneTruth pure = MakeScene("pure_velvet", Options());
  for (float v : pure.base_color.data()) ASSERT_EQ(v, 0.0f);
  for (float v : pure.specular.data()) ASSERT_EQ(v, 0.0f);
  EXPECT_GT(pure.sheen.ChannelMean(0), 0.8);
  const SceneTruth flat = MakeScene("flat_lambertian", Options());
  for (float v : flat.height_mm.data()) ASSERT_EQ(v, 0.0f);
  for (int r = 0; r < kSize; ++r) {
    for (int c = 0; c < kSize; ++c) ASSERT_EQ(flat.normal.at(2, r, c), 1.0f);
  }
  for (float v : flat.roughness.data()) ASSERT_EQ(v, 1.0f);
  for (float v : flat.specular.data()) ASSERT_EQ(v, 0.0f);
  for (float v : flat.sheen.data()) ASSERT_EQ(v, 0.0f);
}

// Lag (pixels) of the highest autocorrelation of the height along rows, searched in [min, max].
int BestRowLag(const SceneTruth& t, int min_lag, int max_lag) {
  const auto& h = t.height_mm;
  double mean = h.ChannelMean(0);
  int best = min_lag;
  double best_score = -1e300;
  for (int lag = min_lag; lag <= max_lag; ++lag) {
    double score = 0.0;
    for (int r = 0; r < h.height(); ++r) {
      for (int c = 0; c + lag < h.width(); ++c) score += (h.at(0, r, c) - mean) * (h.at(0, r, c + lag) - mean);
    }
    score /= (h.width() - lag);
    if (score > best_score) {
      best_score = score;
      best = lag;
    }
  }
  return best;
}

TEST(ScenePresetsTest, ThreadPeriodInMillimetresIsIndependentOfThePitch) {
  for (double dpi : {300.0, 600.0}) {
    const double pitch = 25.4 / dpi;
    const SceneTruth t = MakeScene("plain", Options(9, 96, pitch));
    const double repeat_px = t.repeat_x_mm / pitch;  // plain weave repeats every two warps
    const int lag = BestRowLag(t, static_cast<int>(0.6 * repeat_px), static_cast<int>(1.4 * repeat_px));
    EXPECT_NEAR(lag * pitch, t.repeat_x_mm, pitch) << "dpi " << dpi;
  }
}

TEST(AnalyticScenesTest, BumpsNormalsMatchTheClosedForm) {
  const SceneTruth t = MakeScene("bumps", Options());
  double worst = 0.0;
  for (int r = 0; r < kSize; ++r) {
    for (int c = 0; c < kSize; ++c) {
      const double x = PixelXMm(c, kPitchMm), y = PixelYMm(r, kPitchMm);
      ASSERT_NEAR(t.height_mm.at(0, r, c), BumpsHeightMm(x, y), 1e-6);
      const auto n = BumpsNormal(x, y);
      for (int k = 0; k < 3; ++k) worst = std::max(worst, std::abs(n[k] - t.normal.at(k, r, c)));
    }
  }
  EXPECT_LT(worst, kCentralDifferenceTolerance);
  EXPECT_GT(worst, 0.0);  // it really is a finite-difference normal, not the closed form copied
}

TEST(AnalyticScenesTest, SphereCapNormalsMatchTheClosedFormAwayFromTheRim) {
  const SceneOptions o = Options();
  const SceneTruth t = MakeScene("sphere_cap", o);
  const SphereCap cap = SphereCapFor(o);
  EXPECT_NEAR(t.height_max_mm, cap.cap_height_mm, 1e-6);
  int compared = 0;
  for (int r = 0; r < kSize; ++r) {
    for (int c = 0; c < kSize; ++c) {
      const double x = PixelXMm(c, kPitchMm), y = PixelYMm(r, kPitchMm);
      const double rim = std::hypot(x - cap.center_x_mm, y - cap.center_y_mm) - cap.base_radius_mm;
      if (std::abs(rim) < 2.0 * kPitchMm) continue;  // the crease: no derivative there
      ASSERT_NEAR(t.height_mm.at(0, r, c), SphereCapHeightMm(cap, x, y), 1e-6);
      const auto n = SphereCapNormal(cap, x, y);
      for (int k = 0; k < 3; ++k) ASSERT_NEAR(t.normal.at(k, r, c), n[k], kCentralDifferenceTolerance) << r << "," << c;
      ++compared;
    }
  }
  EXPECT_GT(compared, kSize * kSize * 3 / 4);
}

// The truth of a smooth closed-form surface is its integral over each pixel, not its value at the
// centre: h = A (1 + cos kx cos ky) averages to A (1 + s^2 cos kx cos ky), s = sin(kp/2) / (kp/2).
TEST(AreaAverageTest, BumpsTruthIsTheIntegralOverEachPixel) {
  constexpr int kCoarse = 32, kFactor = 3;
  // The 3-point midpoint rule vs the integral: A k^2 p^2 (1/4 - 1/27... ) ~ 5e-5 mm at 300 dpi;
  // the point sample differs from the integral by up to A (1 - s^2) ~ 9e-4 mm.
  constexpr double kQuadratureToleranceMm = 2e-4;
  const SceneOptions coarse_options = Options(1, kCoarse, kPitchMm);
  const SceneTruth truth = AreaAverageScene(MakeScene("bumps", OversampledSceneOptions(coarse_options, kFactor)), kFactor);
  const double k = 2.0 * std::acos(-1.0) / kBumpsPeriodMm, half = 0.5 * k * kPitchMm;
  const double s = std::sin(half) / half;
  double worst = 0.0, point_worst = 0.0;
  for (int r = 0; r < kCoarse; ++r) {
    for (int c = 0; c < kCoarse; ++c) {
      const double x = PixelXMm(c, kPitchMm), y = PixelYMm(r, kPitchMm);
      const double integral = kBumpsAmplitudeMm * (1.0 + s * s * std::cos(k * x) * std::cos(k * y));
      worst = std::max(worst, std::abs(truth.height_mm.at(0, r, c) - integral));
      point_worst = std::max(point_worst, std::abs(BumpsHeightMm(x, y) - integral));
    }
  }
  EXPECT_LT(worst, kQuadratureToleranceMm);
  EXPECT_GT(point_worst, 2 * kQuadratureToleranceMm);  // the test tells the two apart
}

TEST(AreaAverageTest, HolesBecomePartialCoverage) {
  constexpr int kFactor = 3;
  const SceneOptions coarse_options = Options(2, 24, kPitchMm);
  const SceneTruth t = AreaAverageScene(MakeScene("holes", OversampledSceneOptions(coarse_options, kFactor)), kFactor);
  int partial = 0;
  for (float a : t.alpha.plane(0)) {
    ASSERT_GE(a, 0.0f);
    ASSERT_LE(a, 1.0f);
    partial += a > 0.0f && a < 1.0f;
  }
  EXPECT_GT(partial, 24);  // every yarn edge crosses pixels
}

TEST(AreaAverageTest, RejectsGridsThatAreNotWholeBlocks) {
  const SceneTruth fine = MakeScene("plain", Options(1, 10, kPitchMm));
  EXPECT_THROW(AreaAverageScene(fine, 3), std::invalid_argument);
  EXPECT_THROW(AreaAverageScene(fine, 0), std::invalid_argument);
  EXPECT_THROW(OversampledSceneOptions(Options(), 0), std::invalid_argument);
  EXPECT_EQ(AreaAverageScene(fine, 1).height_mm.data(), fine.height_mm.data());
}

}  // namespace
}  // namespace u3mscan::synthetic
