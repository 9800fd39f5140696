// Photometric stereo on a grid finer than the maps' (pipeline/supersampled_reconstruction.h,
// `process --ps-supersample`): the synthetic plain weave photographed at 600 dpi and processed into
// 300 dpi maps, on the maps' grid (1) and on a grid as fine as the camera resolves (0: auto, 2x),
// against the truth with bench::Evaluate (`u3mscan evaluate`).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <string>

#include "bench/evaluate.h"
#include "capture/stack_builder.h"
#include "datasets_synthetic/synth_run.h"
#include "pipeline/process.h"
#include "pipeline/supersampled_reconstruction.h"
#include "pipeline/tiled_side.h"
#include "pipeline/tiles.h"
#include "tests/support/temp_dir.h"
#include "u3m/image_io.h"

namespace u3mscan {
namespace {

constexpr int kCameraPixels = 192;
constexpr double kCameraDpi = 600.0;
constexpr double kMapDpi = 300.0;
// Measured (fast preset): mean normal error 2.93 -> 2.18 deg, height RMSE 8.6 -> 2.9 % of the
// range. The bounds ask for a clear gain on both, not for these figures.
constexpr double kMaxNormalErrorRatio = 0.85;
constexpr double kMaxHeightErrorRatio = 0.8;

// `scene` on `rig`, its camera at twice the maps' dpi, rendered into dir/synth (TIFF, no
// calibration frames); returns that folder.
std::filesystem::path AtTwiceTheMapsDpi(const test::TempDir& dir, const std::string& scene, const std::string& rig) {
  synthetic::SynthOptions synth;
  synth.scene = scene;
  synth.rig = rig;
  synth.width = synth.height = kCameraPixels;
  synth.dpi = kCameraDpi;
  synth.capture.format = synthetic::FrameFormat::kTiff;
  synth.capture.calibration_frames = false;
  synthetic::RunSynth(synth, dir / "synth");
  return dir / "synth";
}

std::filesystem::path PlainAtTwiceTheMapsDpi(const test::TempDir& dir, const std::string& rig = "distant") {
  return AtTwiceTheMapsDpi(dir, "plain", rig);
}

// The fast preset onto maps at kMapDpi, the debug maps written (for bench::Evaluate).
ProcessOptions FastOntoTheMaps() {
  ProcessOptions options;
  options.preset = Preset::kFast;
  options.dpi = kMapDpi;
  options.debug_maps = true;
  return options;
}

struct ProcessedRun {
  ProcessResult result;
  bench::Evaluation evaluation;
};

// `options` run on the capture of `synth` into dir/name, and evaluated against its truth.
ProcessedRun ProcessAndEvaluate(const test::TempDir& dir, const std::filesystem::path& synth,
                                const ProcessOptions& options, const std::string& name) {
  ProcessedRun run;
  run.result = ProcessCapture({synth / synthetic::kCaptureSubdir, dir / name, name}, options);
  run.evaluation = bench::Evaluate(dir / name, synth / synthetic::kTruthSubdir);
  return run;
}

ProcessedRun Process(const test::TempDir& dir, const std::filesystem::path& synth, int ps_supersample, double max_memory_gib = 4.0,
                     bool fit_on_maps_grid = false) {
  ProcessOptions options = FastOntoTheMaps();
  options.fit_on_maps_grid = fit_on_maps_grid;
  options.ps_supersample = ps_supersample;
  options.max_memory_gib = max_memory_gib;
  std::string name = "k";  // appended piece by piece: "k" + std::string&& trips GCC 12's -Wrestrict
  name += std::to_string(ps_supersample);
  name += '_';
  name += std::to_string(max_memory_gib);
  if (fit_on_maps_grid) name += "_maps_fit";
  ProcessedRun run = ProcessAndEvaluate(dir, synth, options, name);
  std::cout << "[ MEASURED ] --ps-supersample " << ps_supersample << ": normal mean "
            << run.evaluation.normal_mean_deg << " deg, height " << run.evaluation.height_rmse_percent << " %"
            << (fit_on_maps_grid ? ", clusters fitted on the maps' grid" : "");
  const bench::ParameterError& specular = bench::FindParameter(run.evaluation, "specular");
  const bench::ParameterError& roughness = bench::FindParameter(run.evaluation, "roughness");
  std::cout << "; specular " << specular.estimate_mean << " for " << specular.truth_mean << ", roughness error "
            << roughness.mean_abs_error << "\n";
  return run;
}

TEST(SupersampledReconstruction, ACameraAtTwiceTheMapsDpiGivesCloserNormalsAndHeights) {
  test::TempDir dir;
  const auto synth = PlainAtTwiceTheMapsDpi(dir);
  const ProcessedRun on_grid = Process(dir, synth, 1);
  const ProcessedRun finer = Process(dir, synth, 0);
  EXPECT_EQ(on_grid.result.report.options["ps_supersample_front"], 1);
  ASSERT_EQ(finer.result.report.options["ps_supersample_front"], 2);
  EXPECT_NE(FindStep(finer.result.report, "photometric stereo (ls, 2x finer grid)"), nullptr);
  EXPECT_NE(FindStep(finer.result.report, "integration of the fitted normals (on the finer grid)"), nullptr);
  EXPECT_EQ(FindStep(on_grid.result.report, "photometric stereo (ls, 2x finer grid)"), nullptr);
  // One band: after the cast-shadow marks only the pixels a mark changes are solved again, and the
  // report says how many (on the fine grid's solve with the finer grid).
  for (const RunReport* report : {&on_grid.result.report, &finer.result.report}) {
    const StepRecord* marks = FindStep(*report, "cast shadows");
    ASSERT_NE(marks, nullptr);
    EXPECT_NE(marks->reason.find("% of the pixels solved again"), std::string::npos) << marks->reason;
    EXPECT_EQ(marks->reason.find("then 100.0 %"), std::string::npos) << marks->reason;
  }
  ASSERT_GT(finer.evaluation.pixels_compared, 0);
  EXPECT_EQ(finer.evaluation.pixels_compared, on_grid.evaluation.pixels_compared);
  EXPECT_LT(finer.evaluation.normal_mean_deg, kMaxNormalErrorRatio * on_grid.evaluation.normal_mean_deg);
  EXPECT_LT(finer.evaluation.height_rmse_percent, kMaxHeightErrorRatio * on_grid.evaluation.height_rmse_percent);
}

// A budget that holds the maps' stack but not the fine one (four times it at 2x) cuts the scan
// into bands, each solved and refined on its own part of the finer grid (tiled_side.h): the same
// normals, heights and base colour as one band, its clusters fitted on a sample of the finer grid
// and its fine bands' cast shadows marked from heights integrated on the whole finer grid, to
// within the bounds below (measured: 2.169 / 2.171 deg, 3.32 / 3.40 % on a 192 px plain at 600 dpi
// in 3 bands).
constexpr double kMaxBandNormalDifferenceDeg = 0.1;
constexpr double kMaxBandHeightDifferencePercent = 0.5;
// Base colour CIEDE2000, mean over the map: measured 1.03 in one band, 1.00 in 3 (1.23 when the
// fine bands were marked from the maps' heights taken there bilinearly).
constexpr double kMaxBandColourDifference = 0.1;
// Share of the (pixel, observation) pairs marked as cast shadow: measured 0.087 in one band, 0.092
// in 3 (one band reported its maps' stack's share, about 0, before 2026-12-03).
constexpr double kMinFineShadowShare = 0.02;
constexpr double kMaxBandShadowShareDifference = 0.01;

// One band and bands (a budget of 1 / 2.5 of the fine stack) of the same capture, the figures each
// must share within the bounds above checked; the two runs returned for what a caller adds.
struct OneBandAndBands {
  ProcessedRun whole, banded;
};
OneBandAndBands ExpectBandsAsOneBand(const test::TempDir& dir, const std::filesystem::path& synth) {
  OneBandAndBands runs{Process(dir, synth, 0), {}};
  const ProcessedRun& whole = runs.whole;
  EXPECT_EQ(whole.result.report.options["tiles_front"]["bands"], 1);
  const double fine_stack_gib = whole.result.report.options["tiles_front"]["stack_gib"].get<double>();
  runs.banded = Process(dir, synth, 0, fine_stack_gib / 2.5);
  const ProcessedRun& banded = runs.banded;
  EXPECT_GT(banded.result.report.options["tiles_front"]["bands"].get<int>(), 1);
  EXPECT_EQ(banded.result.report.options["ps_supersample_front"], 2);
  EXPECT_NE(FindStep(banded.result.report, "integration of the fitted normals (on the finer grid)"), nullptr);
  EXPECT_GT(banded.evaluation.pixels_compared, 0);
  EXPECT_EQ(banded.evaluation.pixels_compared, whole.evaluation.pixels_compared);
  EXPECT_NEAR(banded.evaluation.normal_mean_deg, whole.evaluation.normal_mean_deg, kMaxBandNormalDifferenceDeg);
  EXPECT_NEAR(banded.evaluation.height_rmse_percent, whole.evaluation.height_rmse_percent, kMaxBandHeightDifferencePercent);
  std::cout << "[ MEASURED ] base colour CIEDE2000: one band " << whole.evaluation.base_color_de_mean << ", "
            << banded.result.report.options["tiles_front"]["bands"] << " bands " << banded.evaluation.base_color_de_mean << "\n";
  EXPECT_NEAR(banded.evaluation.base_color_de_mean, whole.evaluation.base_color_de_mean, kMaxBandColourDifference);
  // The bands' budget is the decode cache's too: the zip TIFF frames beyond it are read by region,
  // and the report says so; one band's 4 GiB keeps every frame whole.
  EXPECT_EQ(FindStep(whole.result.report, "decode cache front"), nullptr);
  const StepRecord* cache = FindStep(banded.result.report, "decode cache front");
  EXPECT_NE(cache, nullptr);
  if (cache) {
    EXPECT_NE(cache->reason.find("read by region on every band read"), std::string::npos) << cache->reason;
  }
  return runs;
}

TEST(SupersampledReconstruction, BandsSolveOnTheFinerGridAsOneBandDoes) {
  test::TempDir dir;
  const OneBandAndBands runs = ExpectBandsAsOneBand(dir, PlainAtTwiceTheMapsDpi(dir));
  const RunReport& banded = runs.banded.result.report;
  EXPECT_NE(FindStep(banded, "photometric stereo (ls, tiled, 2x finer grid)"), nullptr);
  const StepRecord* fit_step = FindStep(banded, "fit");
  ASSERT_NE(fit_step, nullptr);
  EXPECT_NE(fit_step->reason.find("clusters fitted on the 2x finer grid"), std::string::npos) << fit_step->reason;
  // The report's cast-shadow share is photometric stereo's, on the finer grid, in one band as in
  // bands (one band reported its maps' stack's marks, near 0, before 2026-12-03).
  const double whole_share = runs.whole.result.report.quality["front"]["cast_shadow_share"].get<double>();
  const double banded_share = banded.quality["front"]["cast_shadow_share"].get<double>();
  std::cout << "[ MEASURED ] cast-shadow share: one band " << whole_share << ", bands " << banded_share << "\n";
  EXPECT_GT(whole_share, kMinFineShadowShare);
  EXPECT_NEAR(banded_share, whole_share, kMaxBandShadowShareDifference);
}

// The same on the near rig, whose lights' vectors and falloff follow the heights: each near-light
// round integrates its heights on the whole finer grid from the last sweep's fine normals and
// solves and marks the fine bands at them, as one band refines its fine stack. Measured (fast,
// 192 px plain at 600 dpi): one band 1.857 deg, 2.88 %, base colour 1.04; 3 bands 1.881 deg,
// 2.92 %, 1.02. With the maps' heights taken onto the fine bands bilinearly (before 2026-12-03) the
// bands read 1.832 deg, 2.86 % and base colour 1.28, which fails the colour bound.
TEST(SupersampledReconstruction, BandsOfANearRigRefineTheirHeightsOnTheFinerGridAsOneBandDoes) {
  test::TempDir dir;
  const OneBandAndBands runs = ExpectBandsAsOneBand(dir, PlainAtTwiceTheMapsDpi(dir, "near"));
  const StepRecord* solve = FindStep(runs.banded.result.report, "photometric stereo (ls, tiled, 2x finer grid)");
  ASSERT_NE(solve, nullptr);
  EXPECT_NE(solve->reason.find("near point lights, height refined"), std::string::npos) << solve->reason;
  EXPECT_EQ(solve->reason.find("refined 0 rounds"), std::string::npos) << solve->reason;
}

// In bands with distant lights, sweeps reuse earlier sweeps' solves (StageOptions::reuse_band_solves):
// the marked sweep solves again only the pixels a mark changes, and with a finer grid the fit's fine
// pass takes the last sweep's fine normals, albedo and cast-shadow marks instead of solving and
// marking every fine band once more.
// The maps must be bit for bit those of the run that solves everything again, and the report says
// what was reused. Run on the maps' grid (factor 1) and on the 2x finer grid.
void ExpectReusedBandSolvesGiveTheSameMaps(const test::TempDir& dir, const std::filesystem::path& synth, int factor) {
  StageOptions stages = OptionsForPreset(Preset::kFast);
  stages.calibration.dpi = kMapDpi;
  RunReport prepare_report;
  const PreparedCapture prepared = PrepareCapture(synth / synthetic::kCaptureSubdir, stages, &prepare_report);
  const MetricGrid& grid = prepared.calibration.grid;
  const int observations = static_cast<int>(SideSampleFrames(prepared.capture.manifest(), "front").size());
  const TilePlan whole = PlanTiles(grid, observations, /*flats=*/false, 1e12, factor);
  const TilePlan plan = PlanTiles(grid, observations, /*flats=*/false, whole.whole_stack_bytes / 2.5, factor);
  ASSERT_GT(plan.bands, 1);
  ASSERT_EQ(plan.fine_factor, factor);
  auto run = [&](bool reuse, RunReport* report) {
    StageOptions options = stages;
    options.reuse_band_solves = reuse;
    return ProcessSideTiled(prepared, "front", options, plan, Image(), /*residual_observations=*/4, {}, report);
  };
  RunReport reused_report, again_report;
  const TiledSide reused = run(true, &reused_report), again = run(false, &again_report);
  auto reason = [](const RunReport& report, const std::string& step) {
    for (const StepRecord& s : report.steps) {
      if (s.name.rfind(step, 0) == 0) return s.reason;
    }
    return std::string();
  };
  // The cast-shadow step gives the share of the pixels solved again after the marks: all of them
  // without the reuse.
  const std::string reused_marks = reason(reused_report, "cast shadows"), again_marks = reason(again_report, "cast shadows");
  EXPECT_NE(reused_marks.find("% of the pixels solved again"), std::string::npos) << reused_marks;
  EXPECT_EQ(reused_marks.find("then 100.0 %"), std::string::npos) << reused_marks;
  EXPECT_NE(again_marks.find("then 100.0 % of the pixels solved again"), std::string::npos) << again_marks;
  if (factor > 1) {
    EXPECT_NE(reason(reused_report, "fit").find("the last sweep's fine solves kept"), std::string::npos) << reason(reused_report, "fit");
    EXPECT_NE(reason(again_report, "fit").find("solved again"), std::string::npos) << reason(again_report, "fit");
  }
  auto expect_same = [](const Image& a, const Image& b, const char* what) {
    ASSERT_FALSE(a.empty()) << what;
    ASSERT_EQ(a.data().size(), b.data().size()) << what;
    std::size_t differ = 0;
    for (std::size_t i = 0; i < a.data().size(); ++i) differ += a.data()[i] != b.data()[i];
    EXPECT_EQ(differ, 0u) << what;
  };
  expect_same(reused.reconstruction.photometric_stereo.normal, again.reconstruction.photometric_stereo.normal, "normals");
  expect_same(reused.reconstruction.photometric_stereo.albedo, again.reconstruction.photometric_stereo.albedo, "albedo");
  expect_same(reused.reconstruction.height_mm, again.reconstruction.height_mm, "heights");
  expect_same(reused.fit.base_color, again.fit.base_color, "base colour");
  ASSERT_EQ(reused.fit.clusters.size(), again.fit.clusters.size());
  for (std::size_t p = 0; p < reused.fit.parameter_maps.size(); ++p) {
    ASSERT_EQ(reused.fit.parameter_maps[p].empty(), again.fit.parameter_maps[p].empty()) << p;
    if (!reused.fit.parameter_maps[p].empty()) expect_same(reused.fit.parameter_maps[p], again.fit.parameter_maps[p], "a parameter map");
  }
}

TEST(SupersampledReconstruction, BandsReuseTheirEarlierSolvesAndGiveTheSameMaps) {
  test::TempDir dir;
  const auto synth = PlainAtTwiceTheMapsDpi(dir);
  {
    SCOPED_TRACE("2x finer grid");
    ExpectReusedBandSolvesGiveTheSameMaps(dir, synth, 2);
  }
  {
    SCOPED_TRACE("maps' grid");
    ExpectReusedBandSolvesGiveTheSameMaps(dir, synth, 1);
  }
}

TEST(SupersampledReconstruction, ThePhotometricStereoAverageIsPlacedOnThePlanUnlessTurnedOff) {
  // In one band the fine photometric stereo's average (what `reconstruct` writes and the maps' fit
  // starts from) is placed on the plan by the fine heights, as the fit's refined normals are; the
  // report's step says how far the pixels moved. --no-plan-placement averages where the rays met.
  test::TempDir dir;
  const auto synth = PlainAtTwiceTheMapsDpi(dir);
  auto photometric_stereo_step = [](const ProcessResult& result) {
    for (const StepRecord& step : result.report.steps) {
      if (step.name.rfind("photometric stereo (", 0) == 0) return step.reason;
    }
    return std::string("(no photometric stereo step)");
  };
  ProcessOptions options;
  options.preset = Preset::kFast;
  options.dpi = kMapDpi;
  options.ps_supersample = 2;
  const ProcessResult placed = ProcessCapture({synth / synthetic::kCaptureSubdir, dir / "placed", "placed"}, options);
  ASSERT_FALSE(placed.material.empty());
  EXPECT_NE(photometric_stereo_step(placed).find("placed on the plan"), std::string::npos) << photometric_stereo_step(placed);
  options.no_plan_placement = true;
  const ProcessResult on_rays = ProcessCapture({synth / synthetic::kCaptureSubdir, dir / "rays", "rays"}, options);
  ASSERT_FALSE(on_rays.material.empty());
  EXPECT_EQ(photometric_stereo_step(on_rays).find("placed on the plan"), std::string::npos) << photometric_stereo_step(on_rays);
}

// Maps as fine as the camera (no finer grid to use) get 1 from the automatic choice. A factor out
// of range is refused, naming the option.
TEST(SupersampledReconstruction, TheFactorFollowsTheCamera) {
  test::TempDir dir;
  const auto synth = PlainAtTwiceTheMapsDpi(dir);
  ProcessOptions native;
  native.preset = Preset::kFast;
  native.dpi = kCameraDpi;
  native.ps_supersample = 0;
  const ProcessResult at_camera = ProcessCapture({synth / synthetic::kCaptureSubdir, dir / "native", "native"}, native);
  EXPECT_EQ(at_camera.report.options["ps_supersample_front"], 1);
  // Maps at a third of the camera's dpi take its grid (K = 3); at a quarter, one fine pixel more
  // than camera pixels (K = 5, the phases spread); K = 4 there when asked for.
  ProcessOptions third = native;
  third.dpi = kCameraDpi / 3;
  const ProcessResult at_third = ProcessCapture({synth / synthetic::kCaptureSubdir, dir / "third", "third"}, third);
  EXPECT_EQ(at_third.report.options["ps_supersample_front"], 3);
  ProcessOptions quarter = native;
  quarter.dpi = kCameraDpi / 4;
  const ProcessResult at_quarter = ProcessCapture({synth / synthetic::kCaptureSubdir, dir / "quarter", "quarter"}, quarter);
  EXPECT_EQ(at_quarter.report.options["ps_supersample_front"], kMaxAutoPsSupersample);
  quarter.ps_supersample = kSpreadPhasesFromRatio;
  const ProcessResult asked = ProcessCapture({synth / synthetic::kCaptureSubdir, dir / "asked", "asked"}, quarter);
  EXPECT_EQ(asked.report.options["ps_supersample_front"], kSpreadPhasesFromRatio);

  ProcessOptions bad;
  bad.ps_supersample = kMaxPsSupersample + 1;
  std::string why;
  EXPECT_FALSE(bad.Check(&why));
  EXPECT_NE(why.find("--ps-supersample"), std::string::npos) << why;
  bad.ps_supersample = -1;
  EXPECT_FALSE(bad.Check(&why));
}

TEST(SupersampledReconstruction, TheDefaultFactorIsTheFloorOfTheCamerasPixelsPerMapPixelThenOneMore) {
  EXPECT_EQ(PsSupersampleForCameraRatio(0.5), 1);
  EXPECT_EQ(PsSupersampleForCameraRatio(1.0), 1);
  EXPECT_EQ(PsSupersampleForCameraRatio(2.98), 3);  // a dpi rounded down still counts
  EXPECT_EQ(PsSupersampleForCameraRatio(3.5), 3);
  // From 4 camera pixels per map pixel, one fine pixel more than camera pixels: their phases
  // spread (docs/reconstruction.md, "The camera's own pitch").
  EXPECT_EQ(PsSupersampleForCameraRatio(3.97), 5);
  EXPECT_EQ(PsSupersampleForCameraRatio(4.003), 5);
  EXPECT_EQ(PsSupersampleForCameraRatio(5.0), kMaxAutoPsSupersample);
  EXPECT_EQ(PsSupersampleForCameraRatio(1e12), kMaxAutoPsSupersample);
  EXPECT_EQ(kMaxAutoPsSupersample, kSpreadPhasesFromRatio + 1);
  EXPECT_LE(kMaxAutoPsSupersample, kMaxPsSupersample);
  // No camera, or one that resolves nothing: the maps' grid.
  EXPECT_EQ(PsSupersampleForCameraRatio(0.0), 1);
  EXPECT_EQ(PsSupersampleForCameraRatio(-2.0), 1);
  EXPECT_EQ(PsSupersampleForCameraRatio(std::nan("")), 1);
}

// The clusters fitted on the finer grid read the weave's lobe closer to its truth than on the
// maps' grid, where a pixel's mixture of yarn facets looks like a weak broad lobe
// (docs/fitting.md, "Clusters on the finer grid"), with normals no worse: the roughness closer,
// and the specular measured near its truth.
TEST(SupersampledReconstruction, ClustersOnTheFinerGridReadTheLobeCloser) {
  // Measured on this capture (see the test's [ MEASURED ] lines): roughness error 0.046 -> 0.021,
  // specular 0.371 -> 0.388 for 0.5, normals 2.19 -> 2.08 deg.
  constexpr double kMinRoughnessErrorGain = 0.01;  // absolute, on the roughness map's mean error
  constexpr double kSpecularTolerance = 0.15;      // the finer grid's specular against its truth
  constexpr double kNormalSlackDeg = 0.05;
  test::TempDir dir;
  const auto synth = PlainAtTwiceTheMapsDpi(dir);
  const ProcessedRun on_maps = Process(dir, synth, 0, 4.0, /*fit_on_maps_grid=*/true);
  const ProcessedRun on_fine = Process(dir, synth, 0);
  EXPECT_EQ(on_fine.result.report.options["fit_clusters_on_fine_grid"], true);
  EXPECT_EQ(on_maps.result.report.options["fit_clusters_on_fine_grid"], false);
  const StepRecord* fit_step = FindStep(on_fine.result.report, "fit");
  ASSERT_NE(fit_step, nullptr);
  EXPECT_NE(fit_step->reason.find("clusters fitted on the 2x finer grid"), std::string::npos) << fit_step->reason;
  const bench::ParameterError& fine_roughness = bench::FindParameter(on_fine.evaluation, "roughness");
  const bench::ParameterError& maps_roughness = bench::FindParameter(on_maps.evaluation, "roughness");
  ASSERT_TRUE(fine_roughness.measured);
  ASSERT_TRUE(maps_roughness.measured);
  EXPECT_LT(fine_roughness.mean_abs_error, maps_roughness.mean_abs_error - kMinRoughnessErrorGain);
  const bench::ParameterError& fine_specular = bench::FindParameter(on_fine.evaluation, "specular");
  ASSERT_TRUE(fine_specular.measured);
  EXPECT_NEAR(fine_specular.estimate_mean, fine_specular.truth_mean, kSpecularTolerance);
  EXPECT_LT(on_fine.evaluation.normal_mean_deg, on_maps.evaluation.normal_mean_deg + kNormalSlackDeg);
}

TEST(SupersampledReconstruction, WithATiltedViewThePhotographsAreFittedAsTheFinerGridsFacets) {
  // The velvet on the oblique rig (top camera and one at 60 deg) at twice the maps' dpi: the fit
  // stays on the maps' grid (relief registration) and takes the 2x grid's normals as each map
  // pixel's facets (fitting/facet_mixture.h); `--one-normal-per-pixel` fits one normal per pixel.
  test::TempDir dir;
  const auto synth = AtTwiceTheMapsDpi(dir, "velvet", "oblique");
  ProcessOptions options = FastOntoTheMaps();
  auto run = [&](bool one_normal, const std::string& name) {
    options.one_normal_per_pixel = one_normal;
    ProcessedRun out = ProcessAndEvaluate(dir, synth, options, name);
    const bench::ParameterError& sheen = bench::FindParameter(out.evaluation, "sheen");
    std::cout << "[ MEASURED ] " << name << ": sheen " << sheen.estimate_mean << " for " << sheen.truth_mean
              << " (error " << sheen.mean_abs_error << "), roughness error "
              << bench::FindParameter(out.evaluation, "roughness").mean_abs_error << ", re-render "
              << 100.0 * out.evaluation.rerender_relative_rmse << " %\n";
    return out;
  };
  const ProcessedRun facets = run(false, "facets");
  const ProcessedRun one_normal = run(true, "one_normal");
  EXPECT_EQ(facets.result.report.options["fit_facets"], true);
  EXPECT_EQ(one_normal.result.report.options["fit_facets"], false);
  const StepRecord* fit_step = FindStep(facets.result.report, "fit");
  ASSERT_NE(fit_step, nullptr);
  EXPECT_NE(fit_step->reason.find("mixture of the 2x finer grid's facets"), std::string::npos) << fit_step->reason;
  const StepRecord* one_normal_fit = FindStep(one_normal.result.report, "fit");
  ASSERT_NE(one_normal_fit, nullptr);
  EXPECT_EQ(one_normal_fit->reason.find("facets"), std::string::npos) << one_normal_fit->reason;
  EXPECT_TRUE(bench::FindParameter(facets.evaluation, "sheen").measured);
  EXPECT_TRUE(std::isfinite(facets.evaluation.rerender_relative_rmse));
}

// With a tilted view the normals come from the top view's photometric stereo; once the fit knows
// each cluster's lobes they are refined against the top view's photographs on the finer grid
// (pipeline/top_view_normals.h), and `--no-top-view-refinement` keeps photometric stereo's. The
// refinement writes the normals (and the heights' detail) alone: every parameter map is the same
// to the bit. Mean normal error against the truth, measured 2026-12-07 (this capture, fast):
// 1.322 deg without, 1.291 with (1.304 before the refined normals were placed on the plan along
// the top camera's rays); heights (levelled as the run) 0.72 % of the range both (velvet /
// oblique at 4x, balanced: 0.819 -> 0.725 deg, docs/reconstruction.md).
constexpr double kMaxTopViewHeightChangePercent = 0.1;  // of the range, against the truth
TEST(SupersampledReconstruction, WithATiltedViewTheNormalsAreRefinedAgainstTheTopView) {
  test::TempDir dir;
  const auto synth = AtTwiceTheMapsDpi(dir, "velvet", "oblique");
  ProcessOptions options = FastOntoTheMaps();
  auto run = [&](bool refine, const std::string& name) {
    options.no_top_view_refinement = !refine;
    ProcessedRun out = ProcessAndEvaluate(dir, synth, options, name);
    std::cout << "[ MEASURED ] " << name << ": normal mean " << out.evaluation.normal_mean_deg << " deg, height "
              << out.evaluation.height_levelled_rmse_percent << " % (levelled as the run)\n";
    return out;
  };
  const ProcessedRun refined = run(true, "refined");
  const ProcessedRun unrefined = run(false, "unrefined");
  EXPECT_EQ(refined.result.report.options["top_view_refinement"], true);
  EXPECT_EQ(unrefined.result.report.options["top_view_refinement"], false);
  const StepRecord* fit_step = FindStep(refined.result.report, "fit");
  ASSERT_NE(fit_step, nullptr);
  EXPECT_NE(fit_step->reason.find("normals refined on the 2x finer grid against view top alone"), std::string::npos)
      << fit_step->reason;
  // The top view's fine grid is read on the face's plane: its refined normals are placed on the
  // plan by their heights, as a one-camera capture's are (pipeline/view_parallax.h).
  EXPECT_NE(fit_step->reason.find("placed on the plan"), std::string::npos) << fit_step->reason;
  const StepRecord* adopted = FindStep(refined.result.report, "integration of the fitted normals (on the finer grid)");
  ASSERT_NE(adopted, nullptr);
  EXPECT_NE(adopted->reason.find("long wavelengths photometric stereo's"), std::string::npos) << adopted->reason;
  EXPECT_EQ(FindStep(unrefined.result.report, "integration of the fitted normals (on the finer grid)"), nullptr);
  const StepRecord* unrefined_fit = FindStep(unrefined.result.report, "fit");
  ASSERT_NE(unrefined_fit, nullptr);
  EXPECT_EQ(unrefined_fit->reason.find("refined"), std::string::npos) << unrefined_fit->reason;
  // The written normals are the refined ones, and closer to the truth; the heights no worse.
  EXPECT_LT(refined.evaluation.normal_mean_deg, unrefined.evaluation.normal_mean_deg);
  EXPECT_LT(refined.evaluation.height_levelled_rmse_percent,
            unrefined.evaluation.height_levelled_rmse_percent + kMaxTopViewHeightChangePercent);
  // The parameter maps are the fit's on the maps' grid, the same either way.
  for (const char* map : {"base_color", "roughness", "specular", "specular_tint", "sheen", "sheen_tint", "anisotropic"}) {
    const std::filesystem::path a = dir / "refined" / "maps" / (std::string(map) + ".exr");
    const std::filesystem::path b = dir / "unrefined" / "maps" / (std::string(map) + ".exr");
    ASSERT_EQ(std::filesystem::exists(a), std::filesystem::exists(b)) << map;
    if (!std::filesystem::exists(a)) continue;
    const Image ia = ReadImageFile(a, PixelEncoding::kLinear);
    const Image ib = ReadImageFile(b, PixelEncoding::kLinear);
    ASSERT_EQ(ia.pixel_count() * ia.channels(), ib.pixel_count() * ib.channels()) << map;
    for (int c = 0; c < ia.channels(); ++c) {
      EXPECT_TRUE(std::equal(ia.plane(c).begin(), ia.plane(c).end(), ib.plane(c).begin())) << map << " channel " << c;
    }
  }
}

// In bands (a budget of 1 / 2.5 of the fine stack) a tilted view's run fits the same facets as
// one band: the clusters' sample and every band's pixels take their blocks of the last near-light
// round's fine normals (pipeline/tiled_side.cc). Map means, one band / 3 bands, measured
// 2026-12-07: sheen 0.765 / 0.818, sheen tint 0.656 / 0.656, roughness 0.868 / 0.876, specular
// 0.277 / 0.294, specular tint 0.026 / 0.038 (the fast preset's clusters stop at 30 iterations, two
// of four here, so their means move by a few hundredths with any change of their input: with the
// bands' heights integrated on the maps' grid, before that day, sheen read 0.765 / 0.765 and
// specular tint 0.026 / 0.014). Bands fitting one normal a pixel (`--one-normal-per-pixel`, the
// bands' fit before the facets) read 0.843, 0.557, 0.912, 0.277 and 0.452, outside the bound on
// sheen, sheen tint and specular tint.
constexpr double kMaxBandsFacetMapDifference = 0.06;
// The heights, which with a tilted view are the near-light rounds' (the fit does not refine the
// normals): the bands' are the block means of the kept round's fine heights, as one band's are.
// RMS difference of the written (levelled) heights after their means, in % of one band's range:
// measured 0.06 %; 1.53 % when the bands integrated their rounds' heights on the maps' grid from
// the averaged normals (before 2026-12-07; against the truth 1.83 % where one band reads 0.72 %).
constexpr double kMaxBandsHeightDifferencePercent = 0.3;
// The written normals, refined against the top view band by band as one band refines them: mean
// angle between the two maps' normals, measured 0.038 deg (one band's refined normals are 0.30 deg
// from its unrefined ones, so bands that skipped the pass would fail).
constexpr double kMaxBandsNormalDifferenceDeg = 0.1;
TEST(SupersampledReconstruction, WithATiltedViewBandsFitTheFinerGridsFacetsAsOneBandDoes) {
  test::TempDir dir;
  const auto synth = AtTwiceTheMapsDpi(dir, "velvet", "oblique");
  ProcessOptions options = FastOntoTheMaps();
  const auto capture = synth / synthetic::kCaptureSubdir;
  const ProcessResult whole = ProcessCapture({capture, dir / "whole", "whole"}, options);
  ASSERT_EQ(whole.report.options["tiles_front"]["bands"], 1);
  options.max_memory_gib = whole.report.options["tiles_front"]["stack_gib"].get<double>() / 2.5;
  const ProcessResult banded = ProcessCapture({capture, dir / "banded", "banded"}, options);
  ASSERT_GT(banded.report.options["tiles_front"]["bands"].get<int>(), 1);
  EXPECT_EQ(banded.report.options["ps_supersample_front"], 2);
  for (const RunReport* report : {&whole.report, &banded.report}) {
    const StepRecord* fit_step = FindStep(*report, "fit");
    ASSERT_NE(fit_step, nullptr);
    EXPECT_NE(fit_step->reason.find("mixture of the 2x finer grid's facets"), std::string::npos) << fit_step->reason;
    EXPECT_NE(fit_step->reason.find("placed on the plan"), std::string::npos) << fit_step->reason;  // both refine on the plan
  }
  auto mean_of = [](const Image& map) {
    double sum = 0.0;
    for (float v : map.plane(0)) sum += v;
    return sum / static_cast<double>(map.pixel_count());
  };
  for (const char* map : {"sheen", "sheen_tint", "roughness", "specular", "specular_tint"}) {
    const std::filesystem::path in_one_band = dir / "whole" / "maps" / (std::string(map) + ".exr");
    const std::filesystem::path in_bands = dir / "banded" / "maps" / (std::string(map) + ".exr");
    ASSERT_EQ(std::filesystem::exists(in_one_band), std::filesystem::exists(in_bands)) << map;  // measured in both or neither
    if (!std::filesystem::exists(in_one_band)) continue;
    const Image a = ReadImageFile(in_one_band, PixelEncoding::kLinear);
    const Image b = ReadImageFile(in_bands, PixelEncoding::kLinear);
    std::cout << "[ MEASURED ] " << map << " mean, one band " << mean_of(a) << ", bands " << mean_of(b) << "\n";
    EXPECT_NEAR(mean_of(b), mean_of(a), kMaxBandsFacetMapDifference) << map;
  }
  const Image a = ReadImageFile(dir / "whole" / "maps" / "height.exr", PixelEncoding::kLinear);
  const Image b = ReadImageFile(dir / "banded" / "maps" / "height.exr", PixelEncoding::kLinear);
  ASSERT_EQ(a.pixel_count(), b.pixel_count());
  const auto [lo, hi] = std::minmax_element(a.plane(0).begin(), a.plane(0).end());
  const double mean_difference = mean_of(b) - mean_of(a);
  double squares = 0.0;
  for (std::size_t i = 0; i < a.pixel_count(); ++i) {
    const double d = static_cast<double>(b.plane(0)[i]) - a.plane(0)[i] - mean_difference;
    squares += d * d;
  }
  const double difference_percent = 100.0 * std::sqrt(squares / static_cast<double>(a.pixel_count())) / (*hi - *lo);
  std::cout << "[ MEASURED ] heights, RMS difference of bands from one band: " << difference_percent << " % of the range\n";
  EXPECT_LT(difference_percent, kMaxBandsHeightDifferencePercent);
  // The normals, refined against the top view in both (pipeline/top_view_normals.h).
  for (const RunReport* report : {&whole.report, &banded.report}) {
    EXPECT_NE(FindStep(*report, "fit")->reason.find("against view top alone"), std::string::npos);
    const StepRecord* adopted = FindStep(*report, "integration of the fitted normals (on the finer grid)");
    ASSERT_NE(adopted, nullptr);
    EXPECT_NE(adopted->reason.find("long wavelengths photometric stereo's"), std::string::npos) << adopted->reason;
  }
  const Image na = ReadImageFile(dir / "whole" / "maps" / "normal.exr", PixelEncoding::kLinear);
  const Image nb = ReadImageFile(dir / "banded" / "maps" / "normal.exr", PixelEncoding::kLinear);
  ASSERT_EQ(na.pixel_count(), nb.pixel_count());
  double angle_sum = 0.0;
  for (std::size_t i = 0; i < na.pixel_count(); ++i) {
    double dot = 0.0;
    for (int c = 0; c < 3; ++c) dot += static_cast<double>(na.plane(c)[i]) * nb.plane(c)[i];
    angle_sum += std::acos(std::clamp(dot, -1.0, 1.0)) * 180.0 / M_PI;
  }
  const double mean_angle_deg = angle_sum / static_cast<double>(na.pixel_count());
  std::cout << "[ MEASURED ] normals, mean angle of bands' from one band's: " << mean_angle_deg << " deg\n";
  EXPECT_LT(mean_angle_deg, kMaxBandsNormalDifferenceDeg);
}

TEST(SupersampledReconstruction, TheBaseColourFromTheFinerGridIsCloserToTheTruth) {
  // The maps' observations are dimmed in the crevices by yarn shadows their heights cannot mark
  // (pipeline/fine_colour.h); the fine pixels' own colours are not. Measured on this capture (the
  // test's [ MEASURED ] lines): base colour CIEDE2000 1.60 -> 1.03.
  constexpr double kMinColourGain = 0.3;  // CIEDE2000, mean over the map
  test::TempDir dir;
  const auto synth = PlainAtTwiceTheMapsDpi(dir);
  const ProcessedRun on_maps = Process(dir, synth, 0, 4.0, /*fit_on_maps_grid=*/true);
  const ProcessedRun on_fine = Process(dir, synth, 0);
  std::cout << "[ MEASURED ] base colour CIEDE2000: maps' grid " << on_maps.evaluation.base_color_de_mean
            << ", finer grid " << on_fine.evaluation.base_color_de_mean << "\n";
  EXPECT_EQ(on_fine.result.report.options["base_colour_from_fine_grid"], true);
  EXPECT_EQ(on_maps.result.report.options["base_colour_from_fine_grid"], false);
  EXPECT_LT(on_fine.evaluation.base_color_de_mean, on_maps.evaluation.base_color_de_mean - kMinColourGain);
}

}  // namespace
}  // namespace u3mscan
