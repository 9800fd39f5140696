// `u3mscan reconstruct CAPTURE -o DIR`: calibration, rectification, photometric stereo and
// integration of one side, as `process` runs them before its fit (the backlight's holes, a tilted
// view's normals from the most vertical view, the finer grid); writes the maps and prints each
// step's run time.
#include <iostream>
#include <memory>

#include "cli/command.h"
#include "cli/progress_bar.h"
#include "cli/stage_outputs.h"
#include "pipeline/side_run.h"
#include "pipeline/stages.h"
#include "pipeline/supersampled_reconstruction.h"
#include "pipeline/tiles.h"

namespace u3mscan::cli {
namespace {

U3MSCAN_REGISTER_COMMAND(kReconstructCommand, "reconstruct", "Capture -> normal, albedo, height and confidence maps", 40,
                         [](CLI::App& sub) {
  struct Args {
    std::string capture, out, side = "front", solver = "robust", integrator = "dct", level = "plane";
    double dpi = 0.0;
    int ps_supersample = 0;
    bool no_cast_shadows = false;
    bool level_normals = false;
  };
  auto args = std::make_shared<Args>();
  sub.add_option("CAPTURE", args->capture, "Capture folder (with capture.json)")->required();
  sub.add_option("-o,--out", args->out, "Output folder: maps/ goes into it")->required();
  sub.add_option("--solver", args->solver, "Photometric stereo: ls (least squares) | robust (band + IRLS)")
      ->capture_default_str()
      ->check(CLI::IsMember({"ls", "robust"}));
  sub.add_option("--integrator", args->integrator, "Normal integration: dct (Poisson) | robust (keeps edges)")
      ->capture_default_str()
      ->check(CLI::IsMember({"dct", "robust"}));
  sub.add_option("--side", args->side, "front | back")->capture_default_str()->check(CLI::IsMember({"front", "back"}));
  sub.add_option("--dpi", args->dpi, "Resolution of the maps (default: the manifest's)")->check(CLI::Range(1.0, 10000.0));
  sub.add_option("--ps-supersample", args->ps_supersample,
                 "Photometric stereo on a grid K times finer than the maps, the unit normals averaged onto them: 1 = "
                 "off, 2 to 5, 0 = as fine as the top camera resolves (2 or 3 from a 2x or 3x camera, 5 from 4x or more; "
                 "docs/reconstruction.md; without the fit's "
                 "refinement that `process` adds, the height from the averaged normals)")
      ->capture_default_str()
      ->check(CLI::Range(0, kMaxPsSupersample));
  sub.add_flag("--no-cast-shadows", args->no_cast_shadows,
               "Do not mark cast shadows from the heights (they stay dark or outlier data for the solver)");
  sub.add_option("--level", args->level,
                 "The sample's low-order shape taken out of the height map written: none | plane | quadratic "
                 "(as `process --level`, docs/process.md, Levelling)")
      ->capture_default_str()
      ->check(CLI::IsMember({"none", "plane", "quadratic"}));
  sub.add_flag("--level-normals", args->level_normals,
               "Also turn the normal map by the tilt --level removes (as `process --level-normals`)");
  sub.footer(
      "Writes DIR/maps/normal.exr (float, unit, world frame: x right, y up, z toward the camera),\n"
      "DIR/maps/albedo.exr (linear RGB), DIR/maps/height.exr (mm) and DIR/maps/confidence.exr (0..1).\n"
      "As `process` before its fit: holes seen in a backlight frame are masked out of the height, and\n"
      "with a tilted camera the normals come from the most vertical one alone (docs/process.md,\n"
      "Relief registration). `process` then refines the normals with the fitted model.");
  return std::function<int()>([args] {
    StageOptions stages = OptionsForPreset(Preset::kBalanced);
    stages.photometric_stereo.solver = reconstruction::ParsePsSolver(args->solver);
    stages.integration.method = reconstruction::ParseIntegrator(args->integrator);
    stages.photometric_stereo.integration.method = stages.integration.method;
    if (args->dpi > 0.0) stages.calibration.dpi = args->dpi;
    stages.mark_cast_shadows = !args->no_cast_shadows;
    RunReport report;
    ProgressBar bar(false);
    PreparedCapture prepared = PrepareCapture(args->capture, stages, &report, bar.Callback());
    // Holes from the backlight frame, masked out of the integration, as `process` masks them.
    const Image alpha = SideAlpha(prepared, args->side, &report);
    Stack stack = BuildSideStack(prepared, args->side, stages, &report, bar.Callback());
    // A tilted view: the normals from the most vertical view alone, as `process` takes them
    // (StagesForSide; with every view on the face's plane the tilted one's shifted relief and lobes
    // integrate into a ramp). That view moves by hundredths of a pixel on the relief, so its frames
    // stay on the plane here. Otherwise the heights are integrated along the camera's rays.
    stages = StagesForSide(prepared, args->side, stages).options;
    bool flats = false;
    for (const Observation& o : stack.observations) flats = flats || !o.irradiance.empty();
    std::string lowered;
    const int k = ChoosePsSupersample(args->ps_supersample, prepared.calibration, stack,
                                      static_cast<int>(stack.observations.size()), flats, kDefaultStackBudgetGiB * kBytesPerGiB,
                                      &lowered);
    if (!lowered.empty()) report.steps.push_back({"photometric stereo on a finer grid", false, lowered, 0.0});
    SideReconstruction result =
        ReconstructSideSupersampled(prepared, args->side, k, &stack, stages, alpha, &report, bar.Callback());
    report.steps.push_back(LevelSideMaps(reconstruction::ParseLevelling(args->level), args->side, result.valid,
                                         &result.height_mm, args->level_normals ? &result.photometric_stereo.normal : nullptr));
    bar.Finish();
    const auto& ps = result.photometric_stereo;
    WriteStageOutputs(args->out,
                      {{"normal.exr", ps.normal}, {"albedo.exr", ps.albedo}, {"height.exr", result.height_mm},
                       {"confidence.exr", ps.confidence}},
                      {});
    std::cout << "reconstructed " << stack.grid.width << "x" << stack.grid.height << " at " << stack.grid.dpi()
              << " dpi; ill-conditioned pixels: " << ps.ill_conditioned_pixels
              << "; cast shadows: " << 100.0 * result.cast_shadow_share << " % of the observations\n";
    PrintSteps(report);
    std::cout << "maps in " << (std::filesystem::path(args->out) / "maps").string() << "\n";
    return kExitOk;
  });
});

}  // namespace
}  // namespace u3mscan::cli
