// Large scans in bands of rows (docs/process.md, "Large scans: memory and time"): band stacks equal
// the same rows of the whole stack, and a run forced into several bands gives the one-band material
// within named tolerances.
#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <set>
#include <stdexcept>
#include <string>

#include "capture/calibrate.h"
#include "capture/capture.h"
#include "capture/stack_builder.h"
#include "datasets_synthetic/synth_run.h"
#include "pipeline/presets.h"
#include "pipeline/process.h"
#include "pipeline/tiles.h"
#include "u3m/image_io.h"

namespace u3mscan {
namespace {

namespace fs = std::filesystem;

fs::path TestRoot() { return fs::temp_directory_path() / ("u3mscan_tiled_test_" + std::to_string(getpid())); }

// Near point lights (so the near-light rounds run as sweeps), a textured scene, TIFF frames; the
// camera at `camera_per_map` times 300 dpi over the same 80 x 64 px of 300 dpi maps.
fs::path MakeCapture(const std::string& name, bool calibration_frames, int lights, const std::string& scene = "twill",
                     int camera_per_map = 1) {
  const fs::path dir = TestRoot() / name;
  synthetic::SynthOptions options;
  options.scene = scene;
  options.rig = "near";
  options.width = 80 * camera_per_map;
  options.height = 64 * camera_per_map;
  options.dpi = 300.0 * camera_per_map;
  options.lights = lights;
  options.capture.format = synthetic::FrameFormat::kTiff;
  options.capture.calibration_frames = calibration_frames;
  synthetic::RunSynth(options, dir);
  return dir / synthetic::kCaptureSubdir;
}

class TiledTest : public ::testing::Test {
 protected:
  static void TearDownTestSuite() {
    if (!std::getenv("U3MSCAN_KEEP_TEST_OUTPUT")) fs::remove_all(TestRoot());
  }
};

// A relief to rectify on (mm, world z): 0.4 mm of ramp along the rows and +-0.15 mm of ripples
// over the face's plane, so that every grid pixel has its own height.
Image TestRelief(const CalibrationResult& calibration) {
  const MetricGrid& grid = calibration.grid;
  Image z(grid.width, grid.height, 1, 0.0f, grid.pitch_mm);
  for (int r = 0; r < grid.height; ++r) {
    for (int c = 0; c < grid.width; ++c) {
      z.at(0, r, c) = static_cast<float>(calibration.surface_z_mm - 0.4 * r / grid.height + 0.15 * std::sin(0.7 * c));
    }
  }
  return z;
}

// Every observation of every band, bit for bit the same rows of BuildStack's: with dark, ambient
// and flat-field frames, at the native resolution and on a grid coarse enough for the
// anti-aliasing pre-filter (whose reach the band's camera rows must cover); on the face's plane
// and at a relief's heights (the tilted views' registration, pipeline/relief_registration.h).
TEST_F(TiledTest, BandStacksEqualTheRowsOfTheWholeStack) {
  const fs::path dir = MakeCapture("calibrated", /*calibration_frames=*/true, 6);
  const Capture capture = Capture::Open(dir);
  struct Case {
    double dpi;  // 0: native
    bool on_relief;
  };
  for (const Case& t : {Case{0.0, false}, Case{100.0, false}, Case{0.0, true}, Case{100.0, true}}) {
    CalibrationOptions options;
    if (t.dpi > 0.0) options.dpi = t.dpi;
    const CalibrationResult calibration = Calibrate(capture, options);
    ASSERT_FALSE(calibration.flats.empty()) << "the capture should have flat fields";
    const Image relief = t.on_relief ? TestRelief(calibration) : Image();
    const Stack whole = BuildStack(capture, calibration, options, {}, relief);
    const std::vector<std::size_t> frames = SideSampleFrames(capture.manifest(), "front");
    const int h = calibration.grid.height;
    const int edges[] = {0, h / 3, h / 3 + 1, h};  // a one-row band too
    for (int b = 0; b + 1 < 4; ++b) {
      const int row0 = edges[b], rows = edges[b + 1] - edges[b];
      const Stack band = BuildStackRows(capture, calibration, options, frames, row0, rows, {}, relief);
      ASSERT_EQ(band.observations.size(), whole.observations.size());
      EXPECT_DOUBLE_EQ(band.grid.PixelCentreInWorld(0, 0).y(), whole.grid.PixelCentreInWorld(0, row0).y());
      for (std::size_t k = 0; k < whole.observations.size(); ++k) {
        const Observation& w = whole.observations[k];
        const Observation& o = band.observations[k];
        ASSERT_EQ(o.light, w.light);
        ASSERT_EQ(o.rgb.height(), rows);
        int rgb_differ = 0, flags_differ = 0, irradiance_differ = 0;
        for (int r = 0; r < rows; ++r) {
          for (int c = 0; c < whole.grid.width; ++c) {
            for (int ch = 0; ch < 3; ++ch) rgb_differ += o.rgb.at(ch, r, c) != w.rgb.at(ch, row0 + r, c);
            const std::size_t wi = static_cast<std::size_t>(row0 + r) * whole.grid.width + c;
            flags_differ += o.flags[static_cast<std::size_t>(r) * whole.grid.width + c] != w.flags[wi];
            irradiance_differ += o.irradiance.at(0, r, c) != w.irradiance.at(0, row0 + r, c);
          }
        }
        const std::string where = "dpi " + std::to_string(t.dpi) + (t.on_relief ? " on the relief" : " on the plane") +
                                  ", band " + std::to_string(b) + ", observation " + std::to_string(k);
        EXPECT_EQ(rgb_differ, 0) << where;
        EXPECT_EQ(flags_differ, 0) << where;
        EXPECT_EQ(irradiance_differ, 0) << where;
      }
    }
  }
  // A relief of another size than the whole grid is refused.
  CalibrationOptions options;
  const CalibrationResult calibration = Calibrate(capture, options);
  const Image wrong(calibration.grid.width, calibration.grid.height / 2, 1, 0.0f);
  EXPECT_THROW(BuildStackRows(capture, calibration, options, SideSampleFrames(capture.manifest(), "front"), 0, 4, {}, wrong),
               std::invalid_argument);
}

TEST_F(TiledTest, PlanCutsEvenBandsWithinTheBudget) {
  MetricGrid grid;
  grid.width = 5520, grid.height = 3684, grid.pitch_mm = 25.4 / 300;  // 36 MP camera, 75 % of it
  const double budget = 4.0 * (1 << 30);
  const TilePlan plan = PlanTiles(grid, 32, false, budget);
  EXPECT_GT(plan.bands, 1);
  EXPECT_LE(plan.bytes_per_pixel * grid.width * plan.band_rows, budget);
  EXPECT_GE(plan.bands * plan.band_rows, grid.height);
  EXPECT_LT((plan.bands - 1) * plan.band_rows, grid.height);
  EXPECT_LE(plan.whole_stack_bytes / (plan.sample_step * plan.sample_step), kSampleShareOfBudget * budget);
  EXPECT_EQ(PlanTiles(grid, 32, false, 1e12).bands, 1);
  // --ps-supersample 3: each band's stack is 9 times its rows' on the maps' grid, and that is what
  // must fit; the sample stays the maps' grid's.
  constexpr int kFine = 3;
  const TilePlan fine = PlanTiles(grid, 32, false, budget, kFine);
  EXPECT_EQ(fine.fine_factor, kFine);
  EXPECT_LE(fine.bytes_per_pixel * kFine * kFine * grid.width * fine.band_rows, budget);
  EXPECT_GT(fine.bands, plan.bands);
  EXPECT_GE(fine.bands * fine.band_rows, grid.height);
  EXPECT_EQ(fine.sample_step, plan.sample_step);
  EXPECT_DOUBLE_EQ(fine.whole_stack_bytes, kFine * kFine * plan.whole_stack_bytes);
  // A maps' stack that fits in one band whose fine stack does not: bands, with a sample kept
  // within its share of the budget beside them.
  const double between = 2.0 * plan.whole_stack_bytes;
  EXPECT_EQ(PlanTiles(grid, 32, false, between).bands, 1);
  const TilePlan fine_between = PlanTiles(grid, 32, false, between, kFine);
  EXPECT_GT(fine_between.bands, 1);
  EXPECT_LE(plan.whole_stack_bytes / (fine_between.sample_step * fine_between.sample_step), kSampleShareOfBudget * between);
  // Sample grid: pixel i sits on grid pixel k i + k/2.
  const MetricGrid sample = SampleGrid(grid, 4);
  EXPECT_NEAR(sample.PixelCentreInWorld(3, 5).x(), grid.PixelCentreInWorld(4 * 3 + 2, 0).x(), 1e-9);
  EXPECT_NEAR(sample.PixelCentreInWorld(3, 5).y(), grid.PixelCentreInWorld(0, 4 * 5 + 2).y(), 1e-9);
}

// The fine blocks of the sampled pixels: sample pixel (i, j) holds the k x k fine pixels of grid
// pixel (k_s j + k_s / 2, k_s i + k_s / 2), in their order, on the sample grid k times finer.
TEST(SampleFineBlocks, EachSampledPixelGetsItsOwnFineBlock) {
  constexpr int kFine = 3, kStep = 4;
  MetricGrid grid;
  grid.width = 10, grid.height = 7, grid.pitch_mm = 0.1;
  const MetricGrid sample_grid = SampleGrid(grid, kStep);
  // Each fine pixel holds (row, column, channel) as a number of its own.
  Image fine(grid.width * kFine, grid.height * kFine, 2, 0.0f, grid.pitch_mm / kFine);
  for (int c = 0; c < 2; ++c) {
    for (int r = 0; r < fine.height(); ++r) {
      for (int q = 0; q < fine.width(); ++q) fine.at(c, r, q) = static_cast<float>(1000 * r + 10 * q + c);
    }
  }
  const Image blocks = SampleFineBlocks(fine, kFine, kStep, sample_grid);
  ASSERT_EQ(blocks.width(), sample_grid.width * kFine);
  ASSERT_EQ(blocks.height(), sample_grid.height * kFine);
  ASSERT_EQ(blocks.channels(), 2);
  EXPECT_NEAR(blocks.pitch_mm(), sample_grid.pitch_mm / kFine, 1e-12);
  for (int c = 0; c < 2; ++c) {
    for (int i = 0; i < sample_grid.height; ++i) {
      for (int j = 0; j < sample_grid.width; ++j) {
        for (int a = 0; a < kFine; ++a) {
          for (int b = 0; b < kFine; ++b) {
            const int row = (kStep * i + kStep / 2) * kFine + a, col = (kStep * j + kStep / 2) * kFine + b;
            EXPECT_EQ(blocks.at(c, i * kFine + a, j * kFine + b), fine.at(c, row, col)) << i << " " << j;
          }
        }
      }
    }
  }
}

Image ReadMap(const fs::path& out, const std::string& name) {
  return ReadImageFile(out / "maps" / (name + ".exr"), PixelEncoding::kLinear);
}

// The same capture processed whole and in bands (a tiny --max-memory).
TEST_F(TiledTest, SeveralBandsGiveTheOneBandMaterial) {
  const fs::path dir = MakeCapture("plain", /*calibration_frames=*/false, 8);
  ProcessOptions options;
  options.preset = Preset::kFast;  // the suite time limit; the per-pixel step is FitPrincipled's own code
  options.debug_maps = true;
  options.id = "3f2c1a9e-8b7d-4c6e-9a5f-0123456789ab";
  options.created = "2026-11-22T10:00:00Z";
  CaptureJob whole_job{dir, TestRoot() / "whole", "whole"};
  const ProcessResult whole = ProcessCapture(whole_job, options);
  ASSERT_EQ(whole.report.options["tiles_front"]["bands"], 1);
  // About 3 bands: the budget of a third of the whole stack.
  const double stack_gib = whole.report.options["tiles_front"]["stack_gib"];
  options.max_memory_gib = stack_gib / 2.5;
  CaptureJob tiled_job{dir, TestRoot() / "tiled", "tiled"};
  const ProcessResult tiled = ProcessCapture(tiled_job, options);
  const int bands = tiled.report.options["tiles_front"]["bands"];
  const int band_rows = tiled.report.options["tiles_front"]["band_rows"];
  ASSERT_EQ(bands, 3);

  // Photometric stereo is per pixel: identical normals, except pixels regularised toward their
  // neighbours, whose 3x3 neighbourhood a band edge cuts (the row on each side of an edge).
  constexpr int kEdgeReachRows = 1;
  const Image n_whole = ReadMap(whole_job.out_dir, "normal"), n_tiled = ReadMap(tiled_job.out_dir, "normal");
  ASSERT_EQ(n_whole.height(), n_tiled.height());
  int differ = 0, differ_off_edges = 0;
  for (int r = 0; r < n_whole.height(); ++r) {
    bool near_edge = false;
    for (int b = 1; b < bands; ++b) {
      const int edge = b * band_rows;  // first row of band b
      near_edge = near_edge || (r >= edge - kEdgeReachRows && r < edge + kEdgeReachRows);
    }
    for (int c = 0; c < n_whole.width(); ++c) {
      bool same = true;
      for (int ch = 0; ch < 3; ++ch) same = same && n_whole.at(ch, r, c) == n_tiled.at(ch, r, c);
      differ += !same;
      differ_off_edges += !same && !near_edge;
    }
  }
  EXPECT_EQ(differ_off_edges, 0);
  // At most a few percent of the edge rows' pixels are regularised.
  constexpr double kMaxDifferingFraction = 0.01;
  EXPECT_LE(differ, kMaxDifferingFraction * static_cast<double>(n_whole.pixel_count())) << differ << " pixels";

  // Heights: the same integration of nearly the same normals. 1 um is 1/50 of the scene's relief
  // and 50x the difference measured (2e-5 mm mean).
  constexpr double kHeightToleranceMm = 1e-3;
  const Image h_whole = ReadMap(whole_job.out_dir, "height"), h_tiled = ReadMap(tiled_job.out_dir, "height");
  double height_sum = 0.0;
  for (std::size_t i = 0; i < h_whole.pixel_count(); ++i) height_sum += std::abs(h_whole.data()[i] - h_tiled.data()[i]);
  EXPECT_LE(height_sum / static_cast<double>(h_whole.pixel_count()), kHeightToleranceMm);

  // Fit: on a grid this small the sample is the whole grid (kMinSamplePixels), so the clusters are
  // the one-band run's and the per-pixel step, band by band, must give the same maps; only pixels
  // whose normal changed (above) may differ. (The effect of a decimated sample on a large scan is
  // measured in docs/process.md.)
  ASSERT_EQ(tiled.report.options["tiles_front"]["fit_sample_step"], 1);
  // base_color and residual always exist; a parameter map only where the fit measured it (on 8
  // lights and 60 x 48 px the twill's roughness is left out since the normals' uncertainty counts),
  // and then in both runs.
  for (const char* map : {"base_color", "residual", "roughness", "specular", "anisotropic", "anisotropy_rotation"}) {
    const bool in_whole = fs::exists(whole_job.out_dir / "maps" / (std::string(map) + ".exr"));
    ASSERT_EQ(in_whole, fs::exists(tiled_job.out_dir / "maps" / (std::string(map) + ".exr"))) << map;
    if (std::string(map) == "base_color" || std::string(map) == "residual") {
      ASSERT_TRUE(in_whole) << map;
    }
    if (!in_whole) continue;
    const Image a = ReadMap(whole_job.out_dir, map), b = ReadMap(tiled_job.out_dir, map);
    int map_differ = 0;
    for (std::size_t i = 0; i < a.data().size(); ++i) map_differ += a.data()[i] != b.data()[i];
    EXPECT_LE(map_differ, a.channels() * differ) << map;
  }
  EXPECT_EQ(whole.report.quality["front"]["fit_converged"], tiled.report.quality["front"]["fit_converged"]);
}

// --hold-out-lights on a scan processed in bands: the lights' frames stay out of every sweep and the
// check runs band by band; it must give the one-band run's figures.
TEST_F(TiledTest, HeldOutLightsInBandsGiveTheOneBandCheck) {
  const fs::path dir = MakeCapture("held_out", /*calibration_frames=*/false, 8);
  ProcessOptions options;
  options.preset = Preset::kFast;
  options.hold_out_lights = {"L02", "L05"};
  options.id = "3f2c1a9e-8b7d-4c6e-9a5f-0123456789ab";
  options.created = "2026-11-22T10:00:00Z";
  CaptureJob whole_job{dir, TestRoot() / "held_whole", "held_whole"};
  const ProcessResult whole = ProcessCapture(whole_job, options);
  ASSERT_EQ(whole.report.options["tiles_front"]["bands"], 1);
  options.max_memory_gib = whole.report.options["tiles_front"]["stack_gib"].get<double>() / 2.5;
  CaptureJob tiled_job{dir, TestRoot() / "held_tiled", "held_tiled"};
  const ProcessResult tiled = ProcessCapture(tiled_job, options);
  ASSERT_GT(tiled.report.options["tiles_front"]["bands"].get<int>(), 1);

  const nlohmann::json& a = whole.report.quality["front"]["held_out_lights"];
  const nlohmann::json& b = tiled.report.quality["front"]["held_out_lights"];
  ASSERT_TRUE(b.is_object()) << tiled.report.quality.dump();
  ASSERT_EQ(b["lights"].size(), 2u);
  // The maps of the two runs differ only in the few pixels next to a band edge (test above).
  constexpr double kRelativeRmseTolerance = 0.002;
  constexpr double kPixelShareTolerance = 0.01;
  std::cout << "measured: held-out L02, L05 relative RMSE one band " << a["relative_rmse"] << ", in bands "
            << b["relative_rmse"] << "\n";
  EXPECT_NEAR(b["relative_rmse"].get<double>(), a["relative_rmse"].get<double>(), kRelativeRmseTolerance);
  for (std::size_t k = 0; k < 2; ++k) {
    EXPECT_EQ(b["lights"][k]["id"], a["lights"][k]["id"]);
    EXPECT_NEAR(b["lights"][k]["relative_rmse"].get<double>(), a["lights"][k]["relative_rmse"].get<double>(),
                kRelativeRmseTolerance);
    const double pixels = a["lights"][k]["pixels"].get<double>();
    EXPECT_NEAR(b["lights"][k]["pixels"].get<double>(), pixels, kPixelShareTolerance * pixels);
  }
  // The step is reported as in a one-band run.
  bool step = false;
  for (const auto& s : tiled.report.steps) step = step || s.name == "held-out lights front";
  EXPECT_TRUE(step);
}

// --follow-fibres in bands: the maps' grid's turns are read once on its whole normals, as one band
// reads them, so the per-pixel step turns every pixel as one band does (a satin seen by a camera at
// twice the maps' dpi, whose floats the normals resolve; 16 lights so that anisotropic is measured).
TEST_F(TiledTest, BandsFollowTheFibresAsOneBandDoes) {
  const fs::path dir = MakeCapture("fibres", /*calibration_frames=*/false, 16, "satin", 2);
  ProcessOptions options;
  options.preset = Preset::kFast;
  options.follow_fibres = true;
  options.debug_maps = true;
  options.dpi = 300.0;  // photometric stereo and the clusters on the camera's 2x finer grid
  CaptureJob whole_job{dir, TestRoot() / "fibres_whole", "fibres_whole"};
  const ProcessResult whole = ProcessCapture(whole_job, options);
  ASSERT_EQ(whole.report.options["tiles_front"]["bands"], 1);
  EXPECT_EQ(whole.report.options["follow_fibres"], true);
  options.max_memory_gib = whole.report.options["tiles_front"]["stack_gib"].get<double>() / 2.5;
  CaptureJob tiled_job{dir, TestRoot() / "fibres_tiled", "fibres_tiled"};
  const ProcessResult tiled = ProcessCapture(tiled_job, options);
  ASSERT_GT(tiled.report.options["tiles_front"]["bands"].get<int>(), 1);
  const fs::path whole_turns = whole_job.out_dir / "maps" / "anisotropy_rotation.exr";
  const fs::path tiled_turns = tiled_job.out_dir / "maps" / "anisotropy_rotation.exr";
  ASSERT_TRUE(fs::exists(whole_turns));
  ASSERT_TRUE(fs::exists(tiled_turns)) << "the run in bands wrote no rotation texture";
  const Image a = ReadImageFile(whole_turns, PixelEncoding::kLinear), b = ReadImageFile(tiled_turns, PixelEncoding::kLinear);
  ASSERT_EQ(a.pixel_count(), b.pixel_count());
  // One turn per cluster gives at most as many values as clusters; the pixels' own turns give one a pixel.
  auto distinct = [](const Image& turns) {
    std::set<float> values(turns.plane(0).begin(), turns.plane(0).end());
    return values.size();
  };
  const std::size_t clusters = static_cast<std::size_t>(OptionsForPreset(Preset::kFast).fit.clustering.cluster_count);
  EXPECT_GT(distinct(a), 2 * clusters);
  EXPECT_GT(distinct(b), 2 * clusters) << "the bands' pixels kept their clusters' turns only";
  // The same turn as one band's (the clusters come from a sample in bands: measured 2880 of 2880).
  constexpr double kSameTurnDeg = 5.0;
  constexpr double kMinSameShare = 0.95;
  std::size_t same = 0;
  for (std::size_t i = 0; i < a.pixel_count(); ++i) {
    const double d = std::fmod(std::abs(a.plane(0)[i] - b.plane(0)[i]), 180.0);
    same += std::min(d, 180.0 - d) < kSameTurnDeg ? 1 : 0;
  }
  EXPECT_GE(static_cast<double>(same), kMinSameShare * static_cast<double>(a.pixel_count()));
}

}  // namespace
}  // namespace u3mscan
