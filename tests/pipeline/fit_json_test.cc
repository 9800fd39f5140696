// fit.json: every map's decision under its U3M key, what was left out and the value it is written
// as, per-cluster estimates (an infinite std as null), the stage times and options, and free text
// (Ceres messages, reasons) that stays text whatever characters it holds.
#include "pipeline/fit_json.h"

#include <gtest/gtest.h>

#include <limits>
#include <string>

namespace u3mscan::pipeline {
namespace {

using fitting::FitParameter;
using fitting::kFitParameterCount;
using fitting::kRoughness;
using fitting::kSheen;
using fitting::kSpecular;

TEST(FitJson, HoldsTheDecisionsTheClustersAndTheOptionsAsTheyWere) {
  fitting::FitResult result;
  for (int i = 0; i < kFitParameterCount; ++i) {
    result.maps[i].value = fitting::FitParameterDefault(static_cast<FitParameter>(i));
    result.maps[i].reason = "not measured: test";
  }
  result.maps[kRoughness] = {true, false, 0.41, 0.06, "", true, ""};
  result.maps[kSpecular] = {true, true, 0.3, 0.0, "uniform", false, "flagged \"here\"\n"};
  result.rotation_report = {true, true, 90.0, 0.0, "turned", true, ""};
  fitting::ClusterFit cluster;
  cluster.id = 3;
  cluster.pixel_count = 1234;
  cluster.parameters[kRoughness] = {0.41, 0.002, true, "", true, ""};
  cluster.parameters[kSheen] = {0.0, std::numeric_limits<double>::infinity(), false, "no grazing light", true, ""};
  cluster.message = std::string("tab\there, bell\x07, quote \" and backslash \\");
  cluster.pixel_prior_std[kRoughness] = 0.004;  // the per-pixel step's prior; 0 elsewhere
  result.clusters.push_back(cluster);
  result.convergence.messages = {"cluster 3: likely model mismatch"};
  result.times.total_s = 1.5;
  result.options.robust_loss.kind = fitting::RobustLossKind::kCauchy;

  // Through its text, as fit.json is read.
  const nlohmann::json j = nlohmann::json::parse(FitResultToJson(result).dump(2));
  EXPECT_EQ(j["maps"]["roughness"]["u3m"], "roughness");
  EXPECT_EQ(j["maps"]["roughness"]["texture"], true);
  EXPECT_EQ(j["maps"]["roughness"]["value"], 0.41);
  EXPECT_EQ(j["maps"]["specular"]["u3m"], "specular_value");
  EXPECT_EQ(j["maps"]["specular"]["texture"], false) << "a constant is written without a texture";
  EXPECT_EQ(j["maps"]["specular"]["reliable"], false);
  EXPECT_EQ(j["maps"]["specular"]["unreliable_reason"], "flagged \"here\"\n");
  EXPECT_EQ(j["maps"]["anisotropy_rotation"]["unit"], "deg");
  EXPECT_EQ(j["maps"]["anisotropy_rotation"]["value"], 90.0);
  ASSERT_EQ(j["not_measured"].size(), static_cast<std::size_t>(kFitParameterCount - 2));
  EXPECT_EQ(j["not_measured"][0]["parameter"], "specular_tint");
  EXPECT_EQ(j["not_measured"][0]["written_as"], 0.0);
  ASSERT_EQ(j["clusters"].size(), 1u);
  EXPECT_EQ(j["clusters"][0]["id"], 3);
  EXPECT_EQ(j["clusters"][0]["pixels"], 1234);
  EXPECT_EQ(j["clusters"][0]["message"], cluster.message);
  EXPECT_EQ(j["clusters"][0]["parameters"]["roughness"]["std"], 0.002);
  EXPECT_TRUE(j["clusters"][0]["parameters"]["sheen"]["std"].is_null()) << "an infinite std";
  EXPECT_EQ(j["clusters"][0]["pixel_prior_std"], nlohmann::json({{"roughness", 0.004}}))
      << "only the parameters the per-pixel step refines";
  EXPECT_EQ(j["convergence"]["messages"][0], "cluster 3: likely model mismatch");
  EXPECT_EQ(j["times_s"]["total"], 1.5);
  EXPECT_EQ(j["options"]["robust_loss"], "cauchy");
  EXPECT_EQ(j["options"]["mode"], fitting::FitModeName(result.options.mode));
  EXPECT_EQ(j["options"]["pixel_prior_from_samples"], result.options.pixel_prior_from_samples);
  EXPECT_EQ(j["options"]["pixel_prior_std"], result.options.pixel_prior_std);
}

}  // namespace
}  // namespace u3mscan::pipeline
