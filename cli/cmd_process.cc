// `u3mscan process CAPTURE... -o OUT`: the main job. Capture folders (or folders of them) through
// calibration, reconstruction and fitting to complete U3M materials with reports.
#include <iostream>
#include <memory>

#include "cli/command.h"
#include "cli/light_list.h"
#include "cli/progress_bar.h"
#include "core/error.h"
#include "core/logging.h"
#include "core/parallel.h"
#include "pipeline/batch.h"
#include "pipeline/process.h"

namespace u3mscan::cli {
namespace {

struct ProcessArgs {
  std::vector<std::string> inputs;
  std::string out;
  std::string preset = "balanced";
  ProcessOptions options;
  std::string id, created, name;
  std::string hold_out_lights;  // comma-separated light ids (ProcessOptions::hold_out_lights)
  double dpi = 0.0;
  int jobs = 1;
  int threads = 0;
  bool skip_existing = false;
  bool quiet = false;
};

U3MSCAN_REGISTER_COMMAND(kProcessCommand, "process", "Capture folder(s) -> complete U3M material(s) and reports", 1,
                         [](CLI::App& sub) {
  auto args = std::make_shared<ProcessArgs>();
  sub.add_option("CAPTURE", args->inputs, "Capture folders (with capture.json), or folders holding capture folders")
      ->required();
  sub.add_option("-o,--out", args->out, "Output folder (one capture: the material goes straight in; several: one sub-folder each)")
      ->required();
  sub.add_option("--preset", args->preset, "fast | balanced | best: accuracy against run time (docs/presets.md)")
      ->capture_default_str()
      ->check(CLI::IsMember({"fast", "balanced", "best"}));
  sub.add_option("--schema", args->options.schema, "auto | 1.0 | 1.1 (auto: the lowest version that holds the content)")
      ->capture_default_str()
      ->check(CLI::IsMember({"auto", "1.0", "1.1"}));
  sub.add_flag("--package", args->options.package, "Write one .u3ma package instead of .u3m + textures/");
  sub.add_option("--dpi", args->dpi, "Resolution of the finished maps (default: the manifest's output.dpi). Yarn-scale normals need the camera at 2-3x this dpi (docs/reconstruction.md)")
      ->check(CLI::Range(1.0, 10000.0));
  sub.add_flag("--debug-maps", args->options.debug_maps,
               "Also write maps/*.exr: normal, albedo, height (mm), confidence, residual and fitted maps");
  sub.add_option("--solver", args->options.solver, "Override the preset's photometric stereo: ls | robust")
      ->check(CLI::IsMember({"ls", "robust"}));
  sub.add_option("--integrator", args->options.integrator, "Override the preset's integration: dct | robust")
      ->check(CLI::IsMember({"dct", "robust"}));
  sub.add_option("--fit-mode", args->options.fit_mode,
                 "Override the preset's fit: clusters (cluster values only) | per-pixel (refined per pixel)")
      ->check(CLI::IsMember({"clusters", "per-pixel"}));
  sub.add_flag("--no-cast-shadows", args->options.no_cast_shadows,
               "Do not mark cast shadows from the heights (on in every preset; for comparisons)");
  // One string, split by SplitLightIds (cli/light_list.h says why).
  sub.add_option("--hold-out-lights", args->hold_out_lights,
                 "Light ids (the manifest's, comma-separated, e.g. L03,L09) left out of reconstruction and fit; "
                 "the report gives the material's re-render error against their photographs");
  sub.add_option("--ps-supersample", args->options.ps_supersample,
                 "Photometric stereo on a grid K times finer than the maps (a camera at K times their dpi resolves "
                 "it), the normals averaged onto them: 1 = off, 2 to 5, 0 = as fine as the top camera resolves (1 when the "
                 "maps are at its dpi, 2 or 3 from a 2x or 3x camera; 5 from a camera at 4x or more, one fine pixel more "
                 "than camera pixels, which spreads them over its pixels: steadier heights; 4 there runs in about 2/3 of "
                 "the time). "
                 "Closer normals on woven fabric (docs/reconstruction.md); K^2 times the stack's memory (processed in bands "
                 "on the finer grid when that exceeds --max-memory)")
      ->capture_default_str();
  sub.add_flag("--fit-on-maps-grid", args->options.fit_on_maps_grid,
               "With --ps-supersample: fit the clusters and take the base colour on the maps' grid, not the "
               "finer one (for comparisons; docs/fitting.md, Clusters on the finer grid, Base colour from the "
               "finer grid)");
  sub.add_flag("--no-plan-placement", args->options.no_plan_placement,
               "With --ps-supersample: average each fine pixel onto the maps where its camera ray met the grid, not "
               "where its surface point lies in plan (for comparisons; docs/reconstruction.md, Placing the fine "
               "pixels on the plan)");
  sub.add_flag("--one-normal-per-pixel", args->options.one_normal_per_pixel,
               "With a tilted camera and --ps-supersample: fit the photographs with each map pixel's one normal, not "
               "as the mixture of the pixel's finer normals as each camera sees them (for comparisons; docs/fitting.md, "
               "Facets of the finer grid)");
  sub.add_flag("--no-top-view-refinement", args->options.no_top_view_refinement,
               "With a tilted camera and --ps-supersample: write photometric stereo's normals of the top view, not "
               "those refined against its photographs with the fitted lobes (for comparisons; docs/reconstruction.md, "
               "Refining a tilted capture's normals against the top view)");
  sub.add_flag("--follow-fibres", args->options.follow_fibres,
               "Turn the anisotropic stretch per pixel along the fibres the normals show (a lace's cord round its "
               "motif, a satin's floats), each cluster's rotation fitted on top; the rotation is then a texture "
               "(docs/fitting.md, Fibre directions from the relief)");
  sub.add_flag("--one-pixel-prior", args->options.one_pixel_prior,
               "Regularise every pixel toward its cluster with one prior std (0.1), not with the spread each "
               "cluster's samples show (for comparisons; docs/fitting.md, Per-pixel spread from the samples)");
  sub.add_flag("--normal-then-lobe", args->options.normal_then_lobe,
               "Refine each pixel's normal at its cluster's lobe and then its own lobe on that normal, not "
               "the two in one solve (for comparisons; docs/fitting.md, Normal and lobe together)");
  sub.add_option("--level", args->options.levelling,
                 "The sample's low-order shape taken out of the height map: none | plane (a tilt) | "
                 "quadratic (a tilt and a bowl: glossy weaves' normals lean toward the camera into a bowl; also removes a "
                 "sample's real relief over its whole width, docs/process.md, Levelling)")
      ->capture_default_str()
      ->check(CLI::IsMember({"none", "plane", "quadratic"}));
  sub.add_flag("--level-normals", args->options.level_normals,
               "Also turn the normal map by the tilt --level removes (a sample lying tilted on the bed). Off: the "
               "normals are kept as measured, since a fabric whose facets slope more one way (knit) has a mean "
               "slope of its own (docs/process.md, Levelling)");
  sub.add_option("--max-memory", args->options.max_memory_gib,
                 "Memory budget (GiB) of one band's stack (a larger scan is processed in bands of rows) and, "
                 "separately, of the cache of frames kept whole: RAW, PNG, JPEG, compressed TIFF (docs/process.md, Large scans)")
      ->capture_default_str()
      ->check(CLI::Range(1e-6, 1e6));
  sub.add_option("--name", args->name, "File name of the material (one capture only; default: the capture folder's name)");
  sub.add_option("--id", args->id, "Material id (a lowercase version-4 UUID) instead of a new random one");
  sub.add_option("--created", args->created, "Creation time (UTC, 2026-11-22T10:00:00Z) instead of now");
  sub.add_option("--jobs", args->jobs, "Captures processed at the same time (each uses --threads threads)")
      ->capture_default_str()
      ->check(CLI::Range(1, 256));
  sub.add_option("--threads", args->threads, "Threads per capture (default: all cores)")->check(CLI::Range(0, 1024));
  sub.add_flag("--skip-existing", args->skip_existing,
               "Skip captures whose output is complete (material + report.json with status ok): resume a batch");
  sub.add_flag("--quiet", args->quiet, "No progress bar, errors only");
  sub.footer(
      "Writes OUT/<name>.u3m + OUT/textures/ (or OUT/<name>.u3ma), OUT/report.html and OUT/report.json;\n"
      "with several captures, OUT/<name>/ for each and a summary table at the end. One capture that\n"
      "fails is reported and the others still finish. The same input with the same --id and --created\n"
      "gives the same material, so a batch can be split over machines (docs/batch.md).\n"
      "Exit status: 0 all done, 1 some capture failed, 2 bad usage.");
  return std::function<int()>([args] {
    if (args->quiet) SetLogLevel(LogLevel::kError);
    ProcessOptions options = args->options;
    options.preset = ParsePreset(args->preset);
    if (args->dpi > 0.0) options.dpi = args->dpi;
    if (!args->id.empty()) options.id = args->id;
    if (!args->created.empty()) options.created = args->created;
    options.hold_out_lights = SplitLightIds(args->hold_out_lights);
    std::string why;
    if (!options.Check(&why)) {
      LogError() << why;
      return kExitUsage;
    }
    if (args->threads > 0) SetThreadCount(args->threads);

    std::vector<std::filesystem::path> inputs(args->inputs.begin(), args->inputs.end());
    std::vector<CaptureJob> jobs = PlanBatch(inputs, args->out);
    if (!args->name.empty()) {
      if (jobs.size() != 1) {
        LogError() << "--name needs exactly one capture; got " << jobs.size();
        return kExitUsage;
      }
      jobs[0].name = SafeMaterialName(args->name);
    }
    BatchOptions batch;
    batch.parallel_captures = args->jobs;
    batch.skip_existing = args->skip_existing;
    const bool single = jobs.size() == 1;
    const auto outcomes = RunBatch(
        jobs,
        [&](const CaptureJob& job) {
          ProgressBar bar(args->quiet || batch.parallel_captures > 1, single ? "" : job.name + ": ");
          const ProcessResult result = ProcessCapture(job, options, bar.Callback());
          bar.Finish();
          if (!args->quiet) {
            std::cout << job.name << ": wrote " << result.material.string() << " and "
                      << (job.out_dir / "report.html").string() << " (" << result.report.total_seconds << " s)\n";
          }
        },
        [&](const CaptureJob& job) { return IsOutputComplete(job, options); }, batch);
    if (!single || BatchExitCode(outcomes) != 0) std::cout << FormatBatchSummary(outcomes);
    return BatchExitCode(outcomes);
  });
});

}  // namespace
}  // namespace u3mscan::cli
