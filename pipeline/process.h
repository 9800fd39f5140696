#pragma once
// ProcessCapture: one capture folder through calibration, rectification, reconstruction and
// fitting to a complete U3M with its report (the `u3mscan process` command; docs/process.md).
//
// Output (into job.out_dir): <name>.u3m + textures/ (or <name>.u3ma), report.html, report.json and,
// with debug_maps, maps/*.exr. The material is written atomically and report.json last, so a run
// killed midway leaves no material that looks complete (IsOutputComplete) and nothing half-written.
// Two runs on the same input with the same --id and --created write the same material.

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>

#include "core/progress.h"
#include "pipeline/batch.h"
#include "pipeline/presets.h"
#include "pipeline/run_report.h"

namespace u3mscan {

struct ProcessOptions {
  Preset preset = Preset::kBalanced;
  std::string schema = "auto";          // auto | 1.0 | 1.1
  bool package = false;                 // one .u3ma instead of .u3m + textures/
  std::optional<double> dpi;            // overrides the manifest's output dpi
  bool debug_maps = false;              // also write maps/*.exr (normal, albedo, height, confidence, fit maps)
  std::optional<std::string> id;        // material id (lowercase v4 UUID); default: new random
  std::optional<std::string> created;   // UTC "YYYY-MM-DDThh:mm:ssZ"; default: now
  // Overrides of the preset's methods (empty = the preset's choice).
  std::string solver;                   // ls | robust
  std::string integrator;               // dct | robust
  std::string fit_mode;                 // clusters | per-pixel (fitting::FitMode)
  bool no_cast_shadows = false;         // do not mark cast shadows (on in every preset; for comparisons)
  // With --ps-supersample, fit the clusters and take the base colour on the maps' grid instead of
  // the finer one (StageOptions::fit_clusters_on_fine_grid, base_colour_from_fine_grid; for
  // comparisons).
  bool fit_on_maps_grid = false;
  // With --ps-supersample, average the fine pixels onto the maps where their camera rays met the
  // grid instead of where their surface points lie in plan (StageOptions::place_fine_pixels_on_plan;
  // for comparisons).
  bool no_plan_placement = false;
  // With a tilted view and --ps-supersample: fit the photographs with each map pixel's one normal,
  // not as the mixture of its fine normals (StageOptions::fit_facets; for comparisons).
  bool one_normal_per_pixel = false;
  // With a tilted view and --ps-supersample: write photometric stereo's normals of the top view,
  // not those refined against it with the fitted lobes (StageOptions::refine_top_view_normals;
  // for comparisons).
  bool no_top_view_refinement = false;
  // Turn the fit's shading frame per pixel along the fibres the normals show
  // (StageOptions::follow_fibres).
  bool follow_fibres = false;
  // One prior std toward the cluster's value for every pixel (fitting::FitOptions::pixel_prior_std)
  // instead of each cluster's own spread (pixel_prior_from_samples off; for comparisons).
  bool one_pixel_prior = false;
  // Refine each pixel's normal at its cluster's lobe and then its lobe on that normal, not the two
  // together (fitting::FitOptions::refine_normal_with_lobe off; for comparisons).
  bool normal_then_lobe = false;
  // Light ids (the manifest's) left out of reconstruction and fit and re-rendered afterwards: their
  // error against the photographs goes to the report (pipeline/held_out_lights.h), in one band or
  // in bands (tiled_side.h).
  std::vector<std::string> hold_out_lights;
  // Memory budget of one band's stack, GiB: a side whose whole stack (model in pipeline/tiles.h)
  // needs more is processed in bands of rows (docs/process.md, "Large scans: memory and time").
  double max_memory_gib = 4.0;          // = kDefaultStackBudgetGiB
  // Photometric stereo on a grid this many times finer than the maps', the normals averaged onto
  // them (pipeline/supersampled_reconstruction.h): 1 = on the maps' grid, 2 to 5, 0 = as fine as
  // the top camera resolves (PsSupersampleForCameraRatio: the floor of its pixels per map pixel up
  // to 3, 5 from 4 on; the default, which gives 1 when the maps are at the camera's dpi). A side
  // whose fine stack does not fit one band is processed in bands on the finer grid (tiled_side.h).
  int ps_supersample = 0;
  // The sample's low-order shape taken out of the written height and normal maps
  // (reconstruction/relief_levelling.h): none | plane | quadratic. A plane is never part of a
  // material that tiles; a quadratic also removes the bowl that view-dependent lobes leave in the
  // normals of glossy weaves, and with it a sample's real large-scale relief (velvet's crushed
  // regions): docs/process.md, "Levelling".
  std::string levelling = "plane";
  // Also turn the written normals by the removed tilt (`--level-normals`): for a sample that lies
  // tilted on the bed. Off by default: a fabric whose facets slope more one way than the other
  // (knit's loops, each over the next) has normals whose mean slope is its own, and the height's
  // tilt is then that slope integrated over steps the normals cannot see (knit at 1200 dpi, 192 px
  // maps: normals 2.21 deg with the turn, 1.58 without; docs/process.md, "Levelling").
  bool level_normals = false;
  // Returns false and says why when an option is out of range.
  bool Check(std::string* why) const;
};

struct ProcessResult {
  std::filesystem::path material;
  RunReport report;
};

// Throws InputError for bad input (the message names the file, field and expectation) and writes
// nothing then; other exceptions are internal errors.
ProcessResult ProcessCapture(const CaptureJob& job, const ProcessOptions& options, const ProgressCallback& progress = {});

// The material file a job writes (<out_dir>/<name>.u3m or .u3ma).
std::filesystem::path MaterialPathFor(const CaptureJob& job, const ProcessOptions& options);
// True when the job's material and a report.json with status "ok" exist.
bool IsOutputComplete(const CaptureJob& job, const ProcessOptions& options);

}  // namespace u3mscan
