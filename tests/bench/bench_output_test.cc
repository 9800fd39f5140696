// The bench's writers without running the pipeline: the SVG plots parse as XML, the CSV has the
// documented columns on every row, the markdown has its tables, and the quick matrix covers what
// the issue asks (every preset, distant/near/oblique, both methods, a capture that needs less).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>

#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

#include "bench/bench.h"
#include "bench/issue_targets.h"
#include "bench/svg_plot.h"
#include "tests/support/temp_dir.h"

namespace u3mscan::bench {
namespace {

namespace fs = std::filesystem;

// True when the system python's minidom parses the file (an independent XML parser).
bool ParsesAsXml(const fs::path& path) {
  const std::string command = std::string(U3MSCAN_SYSTEM_PYTHON) +
                              " -c \"import sys, xml.dom.minidom; xml.dom.minidom.parse(sys.argv[1])\" '" + path.string() + "'";
  return std::system(command.c_str()) == 0;
}

std::string ReadText(const fs::path& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

std::vector<BenchRow> FakeRows() {
  std::vector<BenchRow> rows;
  int k = 0;
  for (const char* preset : {"fast", "balanced", "best"}) {
    for (const char* rig : {"distant", "near"}) {
      BenchRow r;
      r.c = {"plain", rig, 48, 0, true, preset, "", "", "matrix", "", ""};
      r.lights_used = 16;
      r.megapixels = 0.0023;
      r.solver_used = "robust";
      r.integrator_used = "dct";
      r.total_s = 1.0 + k;
      r.wall_s = 1.1 + k;
      r.peak_rss_mib = 100;
      r.skipped = {"physics", "alpha front"};
      r.evaluation.normal_mean_deg = 1.0 / (1 + k);
      r.evaluation.rerender_relative_rmse = 0.02;
      r.evaluation.parameters.resize(7);
      r.evaluation.parameters[3].measured = false;
      r.evaluation.parameters[3].source = "not measured";
      ++k;
      rows.push_back(r);
    }
  }
  BenchRow failed;
  failed.c = {"velvet", "near", 48, 0, false, "fast", "ls", "", "methods", "", ""};
  failed.status = "failed";
  failed.error = "exit 2: error, with \"quotes\"";
  rows.push_back(failed);
  return rows;
}

TEST(SvgPlot, OutputParsesAsXmlAndEscapesText) {
  const test::TempDir temp;  // removed however the test ends
  const fs::path& dir = temp.path();
  PlotSpec spec{"Error <&> \"time\"", "run time (s)", "error 'deg'"};
  spec.log_x = true;
  std::vector<PlotSeries> series(2);
  series[0].name = "fast & <cheap>";
  series[0].points = {{0.5, 1.0, "a<b"}, {2.0, 0.5, "c&d"}, {-1.0, 2.0, "left out on a log axis"}, {NAN, 1.0, "nan"}};
  series[1].name = "best";
  series[1].connect = true;
  series[1].points = {{3.0, 0.2, "x"}, {1.0, 0.3, "y"}};
  const fs::path path = dir / "plot.svg";
  WriteScatterPlotSvg(spec, series, path);
  EXPECT_TRUE(ParsesAsXml(path));
  const std::string text = ReadText(path);
  EXPECT_NE(text.find("Error &lt;&amp;&gt; &quot;time&quot;"), std::string::npos);
  EXPECT_EQ(text.find("nan"), std::string::npos);
  EXPECT_EQ(text.find("left out"), std::string::npos);
  EXPECT_NE(text.find("<polyline"), std::string::npos);
  // A broken document must fail the check (so the check can fail).
  std::ofstream(dir / "broken.svg") << "<svg><g></svg>";
  EXPECT_FALSE(ParsesAsXml(dir / "broken.svg"));
}

TEST(SvgPlot, EmptyAndSinglePointPlotsAreValid) {
  const test::TempDir temp;  // removed however the test ends
  const fs::path& dir = temp.path();
  WriteScatterPlotSvg(PlotSpec{"empty", "x", "y"}, {}, dir / "empty.svg");
  WriteScatterPlotSvg(PlotSpec{"one", "x", "y"}, {PlotSeries{"s", {{1.0, 1.0, "p"}}, false}}, dir / "one.svg");
  EXPECT_TRUE(ParsesAsXml(dir / "empty.svg"));
  EXPECT_TRUE(ParsesAsXml(dir / "one.svg"));
}

TEST(BenchWriters, CsvHasTheColumnsOnEveryRow) {
  const test::TempDir temp;  // removed however the test ends
  const fs::path& dir = temp.path();
  const auto rows = FakeRows();
  WriteBenchCsv(rows, dir / "bench.csv");
  std::ifstream in(dir / "bench.csv");
  std::string header;
  std::getline(in, header);
  std::string expected;
  for (const auto& c : BenchCsvColumns()) expected += (expected.empty() ? "" : ",") + c;
  EXPECT_EQ(header, expected);
  int lines = 0;
  for (std::string line; std::getline(in, line);) {
    ++lines;
    // Count cells outside quotes.
    int cells = 1;
    bool quoted = false;
    for (char c : line) {
      if (c == '"') quoted = !quoted;
      else if (c == ',' && !quoted) ++cells;
    }
    EXPECT_EQ(cells, static_cast<int>(BenchCsvColumns().size())) << line;
  }
  EXPECT_EQ(lines, static_cast<int>(rows.size()));
}

TEST(BenchWriters, MarkdownAndPlots) {
  const test::TempDir temp;  // removed however the test ends
  const fs::path& dir = temp.path();
  const auto rows = FakeRows();
  BenchOptions options;
  options.quick = true;
  WriteBenchMarkdown(rows, options, dir / "bench.md");
  const std::string md = ReadText(dir / "bench.md");
  for (const char* heading : {"## Every run", "## Against the issues' targets", "## Presets", "## Methods on the same capture", "## Scenes that need less"}) {
    EXPECT_NE(md.find(heading), std::string::npos) << heading;
  }
  EXPECT_NE(md.find("failed: exit 2"), std::string::npos);
  WriteBenchPlots(rows, dir);
  for (const char* plot : {"error_vs_time.svg", "rerender_vs_time.svg", "time_vs_megapixels.svg", "time_vs_lights.svg"}) {
    EXPECT_TRUE(ParsesAsXml(dir / plot)) << plot;
  }
}

// One row per judged run, each figure marked against the issues' limit for its scene.
TEST(IssueTargets, EachFigureIsMarkedAgainstItsLimitAndTheRowCountsWhatItMeets) {
  BenchRow plain;
  plain.c = {"plain", "distant", 128, 0, true, "balanced", "", "", "matrix", "", ""};
  plain.evaluation.scene = "plain";                // truth.json's: it sets the normal's limit
  plain.evaluation.normal_mean_deg = 1.5;          // over plain's 1 deg
  plain.evaluation.base_color_de_mean = 0.5;       // under 1.5
  plain.evaluation.height_rmse_percent = 8.0;      // unlevelled: not the figure judged
  plain.evaluation.height_levelled_rmse_percent = 1.2;
  plain.evaluation.rerender_relative_rmse = 0.05;  // 5 %
  plain.evaluation.rerender_truth_maps_relative_rmse = 0.07;  // shown, not judged
  ParameterError roughness{"roughness", "roughness", "map", true, true, 0.5, 0.52, 0.02, 0.02};
  ParameterError sheen{"sheen", "sheen_value", "not measured", false, true, 0.2, 0.0, NAN, NAN};
  plain.evaluation.parameters = {roughness, sheen};
  BenchRow satin = plain;
  satin.c.scene = "satin";
  satin.evaluation.scene = "satin";                // the same 1.5 deg is within satin's 2
  BenchRow fast = plain;
  fast.c.preset = "fast";                          // only balanced runs are judged
  BenchRow methods = plain;
  methods.c.group = "methods";
  const std::string md = IssueTargetsSection({plain, satin, fast, methods});
  EXPECT_NE(md.find("| plain_distant_128_balanced | 1.50 ✗ | 0.50 ✓ | 1.20 ✓ | 0.020 ✓ |  | not measured | 5.00 ✗ |  | 3 of 5 | 7.00 |"),
            std::string::npos) << md;
  EXPECT_NE(md.find("| satin_distant_128_balanced | 1.50 ✓ |"), std::string::npos) << md;
  EXPECT_EQ(md.find("_fast"), std::string::npos) << md;
  std::size_t plain_rows = 0;
  for (std::size_t at = md.find("| plain_distant_128_balanced |"); at != std::string::npos;
       at = md.find("| plain_distant_128_balanced |", at + 1)) {
    ++plain_rows;
  }
  EXPECT_EQ(plain_rows, 1u) << "the methods group's run of the same id is not judged: " << md;
  // The same verdicts for `u3mscan evaluate`: the sheen left out is judged neither way.
  const nlohmann::json checks = TargetsToJson(CheckAgainstTheTargets(plain.evaluation));
  ASSERT_EQ(checks.size(), 8u);
  EXPECT_EQ(checks[5]["figure"], "sheen err");
  EXPECT_TRUE(checks[5]["not_measured"].get<bool>());
  EXPECT_TRUE(checks[5]["met"].is_null());
  EXPECT_TRUE(checks[7]["value"].is_null()) << "no held-out photographs given";
  EXPECT_EQ(checks[3]["met"], true);
  EXPECT_DOUBLE_EQ(NormalTargetDeg("velvet_mismatch"), kTargetNormalSatinVelvetDeg);
  EXPECT_DOUBLE_EQ(NormalTargetDeg("twill"), kTargetNormalDeg);
}

TEST(BenchMatrix, QuickCoversPresetsRigsMethodsNeedsLessAndHeldOut) {
  BenchOptions options;
  options.quick = true;
  const auto cases = BenchMatrix(options);
  std::set<std::string> presets, rigs, solvers, integrators, fit_modes, ids;
  bool without_calibration = false;
  int held_out = 0, camera_finer = 0, camera_grid_ps = 0, quadratic = 0, mismatch = 0;
  for (const auto& c : cases) {
    mismatch += c.group == "model-mismatch" && c.scene == "velvet_mismatch";
    held_out += !c.hold_out_lights.empty() && c.group == "held-out";
    camera_finer += c.group == "camera-finer" && c.camera_per_map == 2;
    camera_grid_ps += c.group == "camera-finer" && c.ps_supersample == 0;
    quadratic += c.group == "camera-finer" && c.ps_supersample == 0 && c.level == "quadratic";
    if (c.group != "camera-finer") {
      EXPECT_EQ(c.camera_per_map, 1) << c.RunId();
      EXPECT_EQ(c.ps_supersample, 1) << c.RunId();
      EXPECT_EQ(c.level, "plane") << c.RunId();
    }
    presets.insert(c.preset);
    rigs.insert(c.rig);
    if (!c.solver.empty()) solvers.insert(c.solver);
    if (!c.integrator.empty()) integrators.insert(c.integrator);
    if (!c.fit_mode.empty()) fit_modes.insert(c.fit_mode);
    without_calibration = without_calibration || !c.calibration_frames;
    EXPECT_TRUE(ids.insert(c.RunId()).second) << "duplicate run " << c.RunId();
  }
  EXPECT_EQ(presets, (std::set<std::string>{"fast", "balanced", "best"}));
  EXPECT_EQ(rigs, (std::set<std::string>{"distant", "near", "oblique"}));
  EXPECT_EQ(solvers, std::set<std::string>{"ls"});
  EXPECT_EQ(integrators, std::set<std::string>{"robust"});
  EXPECT_EQ(fit_modes, std::set<std::string>{"clusters"}) << "clusters against the balanced run's per-pixel fit";
  EXPECT_TRUE(without_calibration);
  EXPECT_EQ(held_out, 1) << "one run with lights held out of the fit";
  EXPECT_EQ(camera_finer, 3)
      << "a camera at twice the maps' dpi, photometric stereo on the maps' grid and on the camera's (levelled both ways)";
  EXPECT_EQ(camera_grid_ps, 2) << "two runs with --ps-supersample 0";
  EXPECT_EQ(quadratic, 1) << "one of them with --level quadratic";
  EXPECT_EQ(mismatch, 1) << "the velvet of the second reflectance model, beside the Principled velvet's matrix run";
  EXPECT_EQ(std::count_if(cases.begin(), cases.end(),
                          [](const BenchCase& c) { return c.RunId() == "velvet_distant_48_fast" && c.group == "matrix"; }),
            1);
  options.quick = false;
  const auto full = BenchMatrix(options);
  EXPECT_GT(full.size(), cases.size());
  // The full matrix has the camera at 4x (the largest --ps-supersample), solved on its own grid:
  // every fabric on both rigs, plain/distant levelled by a plane and by a quadratic.
  std::multiset<std::string> at_4x;
  for (const BenchCase& c : full) {
    if (c.group == "camera-finer" && c.camera_per_map == 4 && c.ps_supersample == 0) at_4x.insert(c.scene + "/" + c.rig);
  }
  for (const auto& scene : BenchFabricScenes()) {
    EXPECT_EQ(at_4x.count(scene + "/distant"), scene == "plain" ? 2u : 1u) << scene;
    EXPECT_EQ(at_4x.count(scene + "/near"), 1u) << scene;
  }
  // And that 4x plain with lights held out, its maps at 300 dpi and at the camera's 1200.
  std::set<std::string> held_out_at_4x;
  for (const BenchCase& c : full) {
    if (c.group == "held-out" && c.camera_per_map == 4) held_out_at_4x.insert(c.RunId());
  }
  EXPECT_EQ(held_out_at_4x, (std::set<std::string>{"plain_distant_128_cam4x_balanced_pss0_holdout-L02-L05-L09-L14",
                                                   "plain_distant_128_cam4x_balanced_maps1200dpi_pss0_holdout-L02-L05-L09-L14",
                                                   "plain_distant_128_cam4x_nonoise_balanced_maps1200dpi_pss0_holdout-L02-L05-L09-L14"}));
  // Without sensor noise: the 1x plain and the 4x plain with 1200 dpi maps, lights held out.
  EXPECT_EQ(std::count_if(full.begin(), full.end(), [](const BenchCase& c) { return !c.sensor_noise && c.group == "held-out"; }), 2);
  for (const BenchCase& c : cases) {
    EXPECT_DOUBLE_EQ(c.MapsDpi(), 300.0) << c.RunId();
    EXPECT_TRUE(c.sensor_noise) << c.RunId();
    EXPECT_FALSE(c.follow_fibres) << c.RunId();
  }
  // --follow-fibres on the 4x satin, lace and twill, each beside its camera-finer run without it.
  std::set<std::string> fibres, full_ids;
  for (const BenchCase& c : full) full_ids.insert(c.RunId());
  for (const BenchCase& c : full) {
    EXPECT_EQ(c.follow_fibres, c.group == "fibres") << c.RunId();
    if (!c.follow_fibres) continue;
    fibres.insert(c.RunId());
    BenchCase without = c;
    without.follow_fibres = false;
    EXPECT_TRUE(full_ids.count(without.RunId())) << "no run to compare " << c.RunId() << " with";
  }
  EXPECT_EQ(fibres, (std::set<std::string>{"satin_distant_128_cam4x_balanced_pss0_fibres",
                                           "lace_distant_128_cam4x_balanced_pss0_fibres",
                                           "twill_distant_128_cam4x_balanced_pss0_fibres"}));
}

// The fibres table puts each --follow-fibres run under its run without, on the same capture.
TEST(BenchWriters, FibresTableComparesEachRunWithItsRunWithout) {
  BenchRow without;
  without.c = {"lace", "distant", 128, 0, true, "balanced", "", "", "camera-finer", "", ""};
  without.c.camera_per_map = 4;
  without.c.ps_supersample = 0;
  without.evaluation.parameters.resize(7);
  without.evaluation.parameters[5] = {"anisotropic", "anisotropy_value", "map", true, true, 0.19, 0.0, 0.189, -0.189};
  BenchRow with = without;
  with.c.group = "fibres";
  with.c.follow_fibres = true;
  with.evaluation.parameters[5].mean_abs_error = 0.156;
  const test::TempDir temp;
  WriteBenchMarkdown({with, without}, BenchOptions(), temp.path() / "bench.md");
  const std::string md = ReadText(temp.path() / "bench.md");
  const std::size_t table = md.find("## Fibre directions");
  ASSERT_NE(table, std::string::npos) << md;
  const std::size_t no = md.find("| lace_distant_128_cam4x | balanced | no |", table);
  const std::size_t yes = md.find("| lace_distant_128_cam4x | balanced | yes |", table);
  ASSERT_NE(no, std::string::npos) << md.substr(table);
  ASSERT_NE(yes, std::string::npos) << md.substr(table);
  EXPECT_LT(no, yes) << "the run without first";
  EXPECT_NE(md.find("0.1890", no), std::string::npos);
  EXPECT_NE(md.find("0.1560", yes), std::string::npos);
}

}  // namespace
}  // namespace u3mscan::bench
