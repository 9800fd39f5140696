// Evaluate against a known truth: an output that IS the truth gives zero errors; known
// perturbations (normals rotated by 2 deg, roughness shifted by 0.1) are measured as such.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <unistd.h>

#include <filesystem>
#include <iostream>
#include <fstream>

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "bench/evaluate.h"
#include "bench/issue_targets.h"
#include "bench/truth_maps.h"
#include "core/error.h"
#include "datasets_synthetic/truth_writer.h"
#include "reconstruction/relief_levelling.h"
#include "u3m/image_io.h"

namespace u3mscan::bench {
namespace {

namespace fs = std::filesystem;

constexpr int kSize = 64;
constexpr double kPitchMm = 25.4 / 300.0;
constexpr double kZeroTolerance = 1e-3;       // deg, CIEDE2000, mm, parameter units: float round-off
constexpr double kRotationDeg = 2.0;
constexpr double kRotationToleranceDeg = 0.02;  // float32 maps
constexpr double kRoughnessShift = 0.1;
constexpr double kShiftTolerance = 1e-4;
constexpr double kResampleToleranceDeg = 0.05;  // float32 interpolation and renormalisation
// A point sample of each 3 x 3 footprint (its centre truth pixel) on the plain weave at 300 dpi is
// this far from the footprint's mean normal, at least: what comparing with the wrong truth costs.
constexpr double kPointSampleMinErrorDeg = 1.0;
// Re-render error of a material equal to the truth except specular written as its mean constant.
constexpr double kConstantSpecularRerender = 0.01;
// A material holding the velvet's truth maps (specular as its mean constant) re-renders within
// this of the Principled velvet (only the specular spread: measured 0.019), and at least
// kCharlieAgainstDisneyMinRerender from the same velvet rendered with the synthetic scanner's
// Charlie sheen (measured 0.50). Relative RMSE.
constexpr double kVelvetConstantSpecularRerender = 0.03;
constexpr double kCharlieAgainstDisneyMinRerender = 0.2;
// The plain weave's truth maps averaged over 3 x 3 pixels re-render at least this far from their
// facets (relative RMSE; measured 0.036 on this scene, see the test's output).
constexpr double kFacetSpreadMinRerender = 0.02;

void WriteMap(const Image& image, const fs::path& path) {
  ImageWriteOptions options;
  options.format = SampleFormat::kFloat32;
  WriteImageFile(image, path, options);
}

class EvaluateTest : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = fs::temp_directory_path() / ("u3mscan_evaluate_test_" + std::to_string(::getpid()));
    fs::remove_all(root_);
    synthetic::SceneOptions options;
    options.width = options.height = kSize;
    options.pitch_mm = kPitchMm;
    options.seed = 7;
    scene_ = synthetic::MakeScene("plain", options);
    synthetic::WriteTruth(scene_, nullptr, root_ / "truth");
  }
  void TearDown() override { fs::remove_all(root_); }

  // An output folder whose maps are the truth (optionally perturbed), on the same grid.
  fs::path WriteOutput(double rotate_deg, double roughness_shift, bool sheen_measured = false) {
    const fs::path out = root_ / "out";
    fs::remove_all(out);
    fs::create_directories(out / "maps");
    const double half = 0.5 * kSize * kPitchMm;
    // Every parameter as its truth map, except: specular as a constant (its truth mean), sheen
    // "not measured" unless sheen_measured.
    nlohmann::json parameters = nlohmann::json::array();
    // specular is flagged unreliable, as the pipeline's report does it (docs/fitting.md).
    parameters.push_back({{"name", "front/specular_value"}, {"source", "measured (uniform: constant)"},
                          {"value", scene_.specular.ChannelMean(0)}, {"reliable", false},
                          {"unreliable_reason", "test"}});
    parameters.push_back({{"name", "front/sheen_value"},
                          {"source", sheen_measured ? "measured" : "not measured (U3M default)"}, {"value", 0.0}});
    const nlohmann::json report = {
        {"status", "ok"},
        {"calibration", {{"grid", {{"width", kSize}, {"height", kSize}, {"pitch_mm", kPitchMm}, {"region_mm", {-half, -half, half, half}}}}}},
        {"parameters", parameters}};
    std::ofstream(out / "report.json") << report.dump(2);

    Image normal = scene_.normal;
    for (std::size_t i = 0; i < normal.pixel_count(); ++i) {
      const Eigen::Vector3d n(normal.plane(0)[i], normal.plane(1)[i], normal.plane(2)[i]);
      // About an axis perpendicular to the normal, so it turns by exactly rotate_deg.
      const Eigen::Vector3d axis = n.cross(Eigen::Vector3d(1, 2, 0)).normalized();
      const Eigen::Vector3d r = Eigen::AngleAxisd(rotate_deg * M_PI / 180.0, axis) * n;
      for (int c = 0; c < 3; ++c) normal.plane(c)[i] = static_cast<float>(r[c]);
    }
    Image roughness = scene_.roughness;
    for (float& v : roughness.data()) v += static_cast<float>(roughness_shift);
    WriteMap(normal, out / "maps" / "normal.exr");
    WriteMap(scene_.base_color, out / "maps" / "albedo.exr");
    WriteMap(scene_.base_color, out / "maps" / "base_color.exr");
    WriteMap(scene_.height_mm, out / "maps" / "height.exr");
    WriteMap(roughness, out / "maps" / "roughness.exr");
    WriteMap(scene_.specular_tint, out / "maps" / "specular_tint.exr");
    WriteMap(scene_.sheen_tint, out / "maps" / "sheen_tint.exr");
    WriteMap(scene_.anisotropic, out / "maps" / "anisotropic.exr");
    WriteMap(scene_.metallic, out / "maps" / "metallic.exr");
    if (sheen_measured) WriteMap(scene_.sheen, out / "maps" / "sheen.exr");
    return out;
  }

  fs::path root_;
  synthetic::SceneTruth scene_;
};

TEST_F(EvaluateTest, OutputEqualToTruthHasZeroErrors) {
  const Evaluation e = Evaluate(WriteOutput(0.0, 0.0, /*sheen_measured=*/true), root_ / "truth");
  EXPECT_EQ(e.pixels_compared, kSize * kSize);
  EXPECT_NEAR(e.normal_mean_deg, 0.0, kZeroTolerance);
  EXPECT_NEAR(e.normal_p95_deg, 0.0, kZeroTolerance);
  EXPECT_NEAR(e.albedo_de_mean, 0.0, kZeroTolerance);
  EXPECT_NEAR(e.base_color_de_mean, 0.0, kZeroTolerance);
  EXPECT_NEAR(e.height_rmse_mm, 0.0, kZeroTolerance * 1e-3);
  EXPECT_GT(e.height_range_mm, 0.0);
  for (const ParameterError& p : e.parameters) {
    ASSERT_TRUE(p.measured) << p.name;
    if (p.source == "map") {
      EXPECT_NEAR(p.mean_abs_error, 0.0, kZeroTolerance) << p.name;
    }
    EXPECT_NEAR(p.bias, 0.0, kZeroTolerance) << p.name;
  }
  // The rendered truth and the "fit" share normals, colours and every parameter map but the
  // specular constant (= its truth mean), so the re-render differs only by the specular spread.
  EXPECT_EQ(e.parameters[1].source, "constant");
  EXPECT_GT(e.held_out_lights, 0);
  EXPECT_LT(e.rerender_relative_rmse, kConstantSpecularRerender);
  // On the truth's own grid the truth's maps render as the truth: nothing below the fit's figure.
  EXPECT_EQ(e.rerender_truth_maps_relative_rmse, 0.0);
  // The truth itself meets the issues' targets on every figure the evaluation judges.
  EXPECT_EQ(e.scene, "plain");
  for (const TargetCheck& check : CheckAgainstTheTargets(e)) {
    if (check.figure == "held-out photographs %") {
      EXPECT_FALSE(check.Judged()) << "evaluate alone has no held-out photographs";
    } else {
      EXPECT_TRUE(check.Met()) << check.figure << " " << check.value << " against " << check.limit;
    }
  }
}

TEST_F(EvaluateTest, MeasuresKnownPerturbations) {
  const Evaluation e = Evaluate(WriteOutput(kRotationDeg, kRoughnessShift), root_ / "truth");
  EXPECT_NEAR(e.normal_mean_deg, kRotationDeg, kRotationToleranceDeg);
  EXPECT_NEAR(e.normal_median_deg, kRotationDeg, kRotationToleranceDeg);
  EXPECT_NEAR(e.normal_p95_deg, kRotationDeg, kRotationToleranceDeg);
  const ParameterError& roughness = e.parameters[0];
  ASSERT_EQ(roughness.name, "roughness");
  EXPECT_EQ(roughness.source, "map");
  EXPECT_NEAR(roughness.mean_abs_error, kRoughnessShift, kShiftTolerance);
  EXPECT_NEAR(roughness.bias, kRoughnessShift, kShiftTolerance);
  // Specular is the constant of the report (the truth mean): no bias.
  EXPECT_EQ(e.parameters[1].source, "constant");
  EXPECT_NEAR(e.parameters[1].bias, 0.0, kShiftTolerance);
  EXPECT_GT(e.rerender_relative_rmse, 0.01);  // rotated normals and rougher material render differently
  // The rotation is over plain's 1 deg limit; the verdicts say so, in text and JSON.
  ASSERT_GT(kRotationDeg, kTargetNormalDeg);
  const auto checks = CheckAgainstTheTargets(e);
  ASSERT_EQ(checks.front().figure, "normal mean deg");
  EXPECT_TRUE(checks.front().Judged());
  EXPECT_FALSE(checks.front().Met());
  EXPECT_NE(TargetsToText(checks, e.scene).find("issues' targets (scene plain"), std::string::npos);
  EXPECT_EQ(TargetsToJson(checks)[0]["met"], false);
}

TEST_F(EvaluateTest, NotMeasuredParametersAreNotErrors) {
  const Evaluation e = Evaluate(WriteOutput(0.0, 0.0), root_ / "truth");
  const ParameterError& sheen = e.parameters[3];
  ASSERT_EQ(sheen.name, "sheen");
  EXPECT_FALSE(sheen.measured);
  EXPECT_EQ(sheen.source, "not measured");
  EXPECT_TRUE(std::isnan(sheen.mean_abs_error));
  const nlohmann::json j = EvaluationToJson(e);
  EXPECT_TRUE(j["parameters"][3]["mean_abs_error"].is_null());
  EXPECT_NE(EvaluationToText(e).find("not measured"), std::string::npos);
}

TEST_F(EvaluateTest, ReportsWhichValuesTheRunFlaggedUnreliable) {
  const Evaluation e = Evaluate(WriteOutput(0.0, 0.0), root_ / "truth");
  ASSERT_EQ(e.parameters[1].name, "specular");
  EXPECT_FALSE(e.parameters[1].reliable);
  EXPECT_TRUE(e.parameters[0].reliable) << "roughness: no verdict in the report means not flagged";
  EXPECT_FALSE(EvaluationToJson(e)["parameters"][1]["reliable"].get<bool>());
  EXPECT_NE(EvaluationToText(e).find("flagged unreliable"), std::string::npos);
}

TEST_F(EvaluateTest, ResamplesTruthOntoAFinerOutputGrid) {
  // Output at twice the truth's resolution over the same region, holding the truth interpolated
  // bilinearly at the output pixel centres (truth coordinate u = col / 2 - 0.25): zero error only
  // if Evaluate maps the two grids onto each other exactly.
  const fs::path out = WriteOutput(0.0, 0.0);
  const double half = 0.5 * kSize * kPitchMm, fine = kPitchMm / 2;
  std::ofstream(out / "report.json") << nlohmann::json{
      {"calibration", {{"grid", {{"pitch_mm", fine}, {"region_mm", {-half, -half, half, half}}}}}}}.dump();
  Image normal(2 * kSize, 2 * kSize, 3, 0.0f, fine);
  for (int row = 0; row < 2 * kSize; ++row) {
    for (int col = 0; col < 2 * kSize; ++col) {
      const double u = std::clamp(col / 2.0 - 0.25, 0.0, kSize - 1.0), v = std::clamp(row / 2.0 - 0.25, 0.0, kSize - 1.0);
      const int c0 = std::min(static_cast<int>(u), kSize - 2), r0 = std::min(static_cast<int>(v), kSize - 2);
      const double fx = u - c0, fy = v - r0;
      for (int c = 0; c < 3; ++c) {
        const Image& t = scene_.normal;
        normal.at(c, row, col) = static_cast<float>((1 - fy) * ((1 - fx) * t.at(c, r0, c0) + fx * t.at(c, r0, c0 + 1)) +
                                                    fy * ((1 - fx) * t.at(c, r0 + 1, c0) + fx * t.at(c, r0 + 1, c0 + 1)));
      }
    }
  }
  WriteMap(normal, out / "maps" / "normal.exr");
  for (const char* name : {"albedo", "base_color", "height", "roughness", "specular_tint", "sheen_tint", "anisotropic", "metallic"}) {
    fs::remove(out / "maps" / (std::string(name) + ".exr"));
  }
  const Evaluation e = Evaluate(out, root_ / "truth");
  EXPECT_EQ(e.width, 2 * kSize);
  // Pixel centres on the outer quarter-pixel rim fall outside the truth's bilinear support.
  EXPECT_EQ(e.pixels_compared, (2 * kSize - 2) * (2 * kSize - 2));
  EXPECT_LT(e.normal_mean_deg, kResampleToleranceDeg);
  EXPECT_LT(e.normal_p95_deg, kResampleToleranceDeg);
}

TEST_F(EvaluateTest, AveragesTheTruthOverEachPixelOfACoarserOutput) {
  // Output three times coarser than the truth (a camera finer than the finished maps): a map pixel
  // holds the fabric averaged over its 3 x 3 truth pixels. An output holding those averages has no
  // error; one holding the centre truth pixel of each footprint (what bilinear sampling at the
  // output centre would compare with) has.
  constexpr int kFactor = 3, kCoarse = kSize / kFactor;
  const double half = 0.5 * kSize * kPitchMm, coarse_pitch = kFactor * kPitchMm;
  auto write = [&](bool average) {
    const fs::path out = WriteOutput(0.0, 0.0);
    std::ofstream(out / "report.json") << nlohmann::json{
        {"calibration", {{"grid", {{"pitch_mm", coarse_pitch}, {"region_mm", {-half, half - kCoarse * coarse_pitch, -half + kCoarse * coarse_pitch, half}}}}}}}.dump();
    auto reduce = [&](const Image& t, bool unit) {
      Image r(kCoarse, kCoarse, t.channels(), 0.0f, coarse_pitch);
      for (int row = 0; row < kCoarse; ++row) {
        for (int col = 0; col < kCoarse; ++col) {
          Eigen::Vector3d v = Eigen::Vector3d::Zero();
          for (int c = 0; c < t.channels(); ++c) {
            if (!average) {
              v[c] = t.at(c, kFactor * row + 1, kFactor * col + 1);
              continue;
            }
            for (int j = 0; j < kFactor; ++j) {
              for (int i = 0; i < kFactor; ++i) v[c] += t.at(c, kFactor * row + j, kFactor * col + i) / (kFactor * kFactor);
            }
          }
          if (unit) v.normalize();
          for (int c = 0; c < t.channels(); ++c) r.at(c, row, col) = static_cast<float>(v[c]);
        }
      }
      return r;
    };
    WriteMap(reduce(scene_.normal, true), out / "maps" / "normal.exr");
    WriteMap(reduce(scene_.base_color, false), out / "maps" / "albedo.exr");
    WriteMap(reduce(scene_.base_color, false), out / "maps" / "base_color.exr");
    WriteMap(reduce(scene_.height_mm, false), out / "maps" / "height.exr");
    WriteMap(reduce(scene_.roughness, false), out / "maps" / "roughness.exr");
    for (const char* name : {"specular_tint", "sheen_tint", "anisotropic", "metallic"}) fs::remove(out / "maps" / (std::string(name) + ".exr"));
    return Evaluate(out, root_ / "truth");
  };
  const Evaluation averaged = write(true);
  EXPECT_EQ(averaged.width, kCoarse);
  EXPECT_EQ(averaged.pixels_compared, kCoarse * kCoarse);  // every footprint lies on the fabric
  EXPECT_LT(averaged.normal_mean_deg, kResampleToleranceDeg);
  EXPECT_LT(averaged.albedo_de_mean, kZeroTolerance);
  EXPECT_LT(averaged.height_rmse_mm, kZeroTolerance);
  EXPECT_LT(averaged.parameters[0].mean_abs_error, kShiftTolerance);  // roughness
  const Evaluation point = write(false);
  std::cout << "measured: 3x coarser output, footprint means " << averaged.normal_mean_deg << " deg, centre samples "
            << point.normal_mean_deg << " deg; the truth's own maps re-render to "
            << 100.0 * averaged.rerender_truth_maps_relative_rmse << " %\n";
  EXPECT_GT(point.normal_mean_deg, kPointSampleMinErrorDeg);
  // The truth's own maps on the coarser grid: each pixel's mean normal and parameters render
  // otherwise than its 3 x 3 facets. A property of the truth and the grid, not of the output.
  EXPECT_GT(averaged.rerender_truth_maps_relative_rmse, kFacetSpreadMinRerender);
  EXPECT_DOUBLE_EQ(averaged.rerender_truth_maps_relative_rmse, point.rerender_truth_maps_relative_rmse);
}

// Sets report.json /options/levelling of an output folder.
void SetLevelling(const fs::path& out, const nlohmann::json& levelling) {
  nlohmann::json report = nlohmann::json::parse(std::ifstream(out / "report.json"));
  report["options"]["levelling"] = levelling;
  std::ofstream(out / "report.json") << report.dump(2);
}

TEST_F(EvaluateTest, ALevelledRunIsAlsoComparedWithTheTruthLevelledAlike) {
  // The truth holds a tilt of its own (kTiltMm across the map in x); the run wrote the relief with
  // the tilt taken out (--level plane), as the pipeline does. Against the truth as it is, the tilt
  // counts as error; against the truth levelled alike, nothing is left.
  constexpr double kTiltMm = 0.05;
  synthetic::SceneTruth tilted = scene_;
  for (int r = 0; r < kSize; ++r)
    for (int c = 0; c < kSize; ++c) tilted.height_mm.at(0, r, c) += static_cast<float>(kTiltMm * c / (kSize - 1));
  const fs::path truth = root_ / "tilted_truth";
  synthetic::WriteTruth(tilted, nullptr, truth);
  const fs::path out = WriteOutput(0.0, 0.0);
  Image levelled = tilted.height_mm;
  reconstruction::LevelRelief(reconstruction::Levelling::kPlane, &levelled, nullptr);
  WriteMap(levelled, out / "maps" / "height.exr");

  // No levelling in the report: one figure, the tilt's RMS (a ramp of kTiltMm: kTiltMm / sqrt(12))
  // plus what taking out the truth's own small plane moved.
  const Evaluation plain = Evaluate(out, truth);
  EXPECT_EQ(plain.height_levelling, "none");
  EXPECT_TRUE(std::isnan(plain.height_levelled_rmse_mm));
  EXPECT_GT(plain.height_rmse_mm, 0.5 * kTiltMm / std::sqrt(12.0));
  EXPECT_EQ(EvaluationToText(plain).find("truth levelled"), std::string::npos);

  SetLevelling(out, "plane");
  const Evaluation level = Evaluate(out, truth);
  EXPECT_EQ(level.height_levelling, "plane");
  EXPECT_NEAR(level.height_rmse_mm, plain.height_rmse_mm, kZeroTolerance * 1e-3);  // the first figure is unchanged
  EXPECT_NEAR(level.height_levelled_rmse_mm, 0.0, kZeroTolerance * 1e-3);
  EXPECT_NEAR(level.height_levelled_rmse_percent, 0.0, kZeroTolerance);
  EXPECT_NE(EvaluationToText(level).find("truth levelled (plane"), std::string::npos);
  EXPECT_TRUE(EvaluationToJson(level)["height"]["truth_levelled"]["rmse_mm"].is_number());

  SetLevelling(out, "tilted");
  EXPECT_THROW(Evaluate(out, truth), InputError);
}

// Under model mismatch the fabric is what the scene's own model renders: a Principled material
// holding the truth's maps is then measured against the Charlie sheen it cannot reproduce, not
// against a Principled rendering of the same parameters (which it would match).
TEST_F(EvaluateTest, TheTruthIsRenderedWithTheModelItsSceneWasRenderedWith) {
  synthetic::SceneOptions options;
  options.width = options.height = kSize;
  options.pitch_mm = kPitchMm;
  options.seed = 7;
  for (const std::string name : {"velvet", "velvet_mismatch"}) {
    scene_ = synthetic::MakeScene(name, options);
    synthetic::WriteTruth(scene_, nullptr, root_ / name);
    const Evaluation e = Evaluate(WriteOutput(0.0, 0.0, /*sheen_measured=*/true), root_ / name);
    std::cout << name << ": re-render " << e.rerender_relative_rmse << ", the truth's own maps "
              << e.rerender_truth_maps_relative_rmse << "\n";
    ASSERT_GT(e.held_out_lights, 0);
    if (name == "velvet") {
      EXPECT_LT(e.rerender_relative_rmse, kVelvetConstantSpecularRerender);
      EXPECT_EQ(e.rerender_truth_maps_relative_rmse, 0.0);
      EXPECT_EQ(EvaluationToJson(e)["rerender"]["truth_reflectance_model"], "principled");
    } else {
      EXPECT_EQ(EvaluationToJson(e)["rerender"]["truth_reflectance_model"], "cloth_mismatch");
      EXPECT_NE(EvaluationToText(e).find("cloth_mismatch (model mismatch)"), std::string::npos) << EvaluationToText(e);
      EXPECT_GT(e.rerender_relative_rmse, kCharlieAgainstDisneyMinRerender);
      EXPECT_GT(e.rerender_truth_maps_relative_rmse, kCharlieAgainstDisneyMinRerender);
    }
  }
}

TEST_F(EvaluateTest, AnUnknownReflectanceModelIsAnInputErrorAndAnAbsentOneIsPrincipled) {
  const fs::path file = root_ / "truth" / "truth.json";
  nlohmann::json truth = nlohmann::json::parse(std::ifstream(file));
  truth["reflectance_model"] = "lambert";
  std::ofstream(file) << truth.dump();
  try {
    ReadTruthMaps(root_ / "truth");
    ADD_FAILURE() << "an unknown reflectance model was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("/reflectance_model"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("truth.json"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("\"principled\" or \"cloth_mismatch\""), std::string::npos) << e.what();
  }
  truth.erase("reflectance_model");
  std::ofstream(file) << truth.dump();
  EXPECT_EQ(ReadTruthMaps(root_ / "truth").model, synthetic::ReflectanceModel::kPrincipled);
}

TEST_F(EvaluateTest, MissingDebugMapsIsAnInputError) {
  const fs::path out = WriteOutput(0.0, 0.0);
  fs::remove(out / "maps" / "normal.exr");
  EXPECT_THROW(Evaluate(out, root_ / "truth"), InputError);
  EXPECT_THROW(Evaluate(root_ / "nowhere", root_ / "truth"), InputError);
}

}  // namespace
}  // namespace u3mscan::bench
