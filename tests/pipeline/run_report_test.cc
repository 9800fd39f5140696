#include "pipeline/run_report.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <sstream>

#include "pipeline/stages.h"

namespace u3mscan {
namespace {

namespace fs = std::filesystem;

std::string ReadText(const fs::path& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

RunReport ExampleReport() {
  RunReport report;
  report.capture_name = "plain <weave> & co";
  report.preset = "balanced";
  report.steps.push_back({"colour correction", false, "no chart frames", 0.0});
  report.steps.push_back({"photometric stereo", true, "", 1.25});
  report.parameters.push_back({"sheen", ParameterSource::kDefault, "overhead camera only", 0.0, 0.0, ""});
  report.parameters.push_back({"roughness", ParameterSource::kMeasured, "", 0.62, 0.01, ""});
  report.quality["mean_confidence"] = 0.93;
  Image gradient(8, 4, 1);
  for (int x = 0; x < 8; ++x) gradient.at(0, 0, x) = static_cast<float>(x);
  report.images.push_back({"height", "map", gradient, false});
  report.images.push_back({"albedo", "map", Image(8, 4, 3, 0.5f), true});
  return report;
}

TEST(RunReport, HtmlIsSelfContainedAndEscaped) {
  const fs::path dir = fs::temp_directory_path() / "u3mscan_report_test";
  fs::create_directories(dir);
  const fs::path html_path = dir / "report.html";
  WriteReportHtml(ExampleReport(), html_path);
  const std::string html = ReadText(html_path);
  EXPECT_NE(html.find("plain &lt;weave&gt; &amp; co"), std::string::npos);
  EXPECT_EQ(html.find("<weave>"), std::string::npos) << "raw markup from a capture name must be escaped";
  EXPECT_NE(html.find("no chart frames"), std::string::npos);
  EXPECT_NE(html.find("not measured (U3M default)"), std::string::npos);
  // Two embedded PNG thumbnails (base64 of the PNG signature starts with iVBORw0KGgo).
  std::size_t count = 0;
  for (std::size_t pos = html.find("data:image/png;base64,iVBORw0KGgo"); pos != std::string::npos;
       pos = html.find("data:image/png;base64,iVBORw0KGgo", pos + 1)) {
    ++count;
  }
  EXPECT_EQ(count, 2u);
  EXPECT_EQ(html.find("http"), std::string::npos) << "no network references";
  EXPECT_FALSE(fs::exists(html_path.string() + ".partial"));
  fs::remove_all(dir);
}

TEST(RunReport, JsonHasEveryFigure) {
  const nlohmann::json j = RunReportToJson(ExampleReport());
  EXPECT_EQ(j["preset"], "balanced");
  ASSERT_EQ(j["steps"].size(), 2u);
  EXPECT_FALSE(j["steps"][0]["ran"].get<bool>());
  EXPECT_EQ(j["steps"][0]["reason"], "no chart frames");
  EXPECT_DOUBLE_EQ(j["steps"][1]["seconds"].get<double>(), 1.25);
  EXPECT_EQ(j["parameters"][0]["source"], "not measured (U3M default)");
  EXPECT_DOUBLE_EQ(j["quality"]["mean_confidence"].get<double>(), 0.93);
}

// The fit step says where its time went, stage by stage (fitting::StageTimes), after what it did.
TEST(RunReport, TheFitStepGivesTheTimeOfEachStage) {
  fitting::FitResult fit;
  fit.times.gather_s = 1.3;
  fit.times.clustering_s = 0.5;
  fit.times.cluster_fit_s = 12.0;
  fit.times.observability_s = 3.0;
  fit.times.per_pixel_s = 40.0;
  RunReport report;
  ReportFitStep(fit, "8 clusters", 54.0, &report);
  ASSERT_EQ(report.steps.size(), 1u);
  const StepRecord& step = report.steps[0];
  EXPECT_EQ(step.name, "fit");
  EXPECT_TRUE(step.ran);
  EXPECT_DOUBLE_EQ(step.seconds, 54.0);
  EXPECT_EQ(step.reason,
            "8 clusters; gather 1.3 s, clustering 0.5 s, cluster fits 12.0 s (observability 3.0 s of it), pixels 40.0 s");
}

}  // namespace
}  // namespace u3mscan
