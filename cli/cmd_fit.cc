// `u3mscan fit CAPTURE -o DIR`: everything up to the Principled fit of one side, as `process` runs
// it (pipeline/side_run.h: relief registration, the finer grid's facets, bands); writes the fitted
// parameter maps as float EXR and fit.json (per-cluster parameters, uncertainties, what was left
// out and why, run times, and with --hold-out-lights the material's error on those lights).
#include <iostream>
#include <memory>

#include "cli/command.h"
#include "cli/light_list.h"
#include "cli/progress_bar.h"
#include "cli/stage_outputs.h"
#include "pipeline/fit_json.h"
#include "pipeline/side_run.h"
#include "pipeline/stages.h"
#include "pipeline/supersampled_reconstruction.h"

namespace u3mscan::cli {
namespace {

U3MSCAN_REGISTER_COMMAND(kFitCommand, "fit", "Capture -> fitted Principled parameter maps and fit.json", 50,
                         [](CLI::App& sub) {
  struct Args {
    std::string capture, out, side = "front", preset = "balanced", fit_mode, hold_out_lights;
    double dpi = 0.0;
    SideRunOptions run;
    bool follow_fibres = false;
    bool one_pixel_prior = false;
    bool normal_then_lobe = false;
  };
  auto args = std::make_shared<Args>();
  sub.add_option("CAPTURE", args->capture, "Capture folder (with capture.json)")->required();
  sub.add_option("-o,--out", args->out, "Output folder: maps/ and fit.json go into it")->required();
  sub.add_option("--preset", args->preset, "fast | balanced | best")
      ->capture_default_str()
      ->check(CLI::IsMember({"fast", "balanced", "best"}));
  sub.add_option("--side", args->side, "front | back")->capture_default_str()->check(CLI::IsMember({"front", "back"}));
  sub.add_option("--fit-mode", args->fit_mode,
                 "Override the preset's fit: clusters (cluster values only) | per-pixel (refined per pixel)")
      ->check(CLI::IsMember({"clusters", "per-pixel"}));
  sub.add_option("--dpi", args->dpi, "Resolution of the maps (default: the manifest's)")->check(CLI::Range(1.0, 10000.0));
  sub.add_option("--ps-supersample", args->run.ps_supersample,
                 "Photometric stereo on a grid K times finer than the maps, as `process --ps-supersample`: 1 = off, "
                 "2 to " + std::to_string(kMaxPsSupersample) + ", 0 = as fine as the top camera resolves")
      ->capture_default_str()
      ->check(CLI::Range(0, kMaxPsSupersample));
  sub.add_option("--max-memory", args->run.max_memory_gib,
                 "Memory budget (GiB) of one band's stack, as `process --max-memory`: a larger scan is fitted in "
                 "bands of rows")
      ->capture_default_str()
      ->check(CLI::Range(1e-6, 1e6));
  sub.add_option("--hold-out-lights", args->hold_out_lights,
                 "Light ids (comma-separated, e.g. L03,L09) left out of reconstruction and fit; fit.json "
                 "(\"held_out_lights\") gives the fitted material's re-render error against their photographs");
  sub.add_flag("--follow-fibres", args->follow_fibres,
               "Turn the anisotropic stretch per pixel along the fibres the normals show, as `process "
               "--follow-fibres` does (docs/fitting.md, Fibre directions from the relief)");
  sub.add_flag("--one-pixel-prior", args->one_pixel_prior,
               "Regularise every pixel toward its cluster with one prior std (0.1), not with the spread each "
               "cluster's samples show (for comparisons; docs/fitting.md, Per-pixel spread from the samples)");
  sub.add_flag("--normal-then-lobe", args->normal_then_lobe,
               "Refine each pixel's normal at its cluster's lobe and then its own lobe on that normal, not "
               "the two in one solve (for comparisons; docs/fitting.md, Normal and lobe together)");
  sub.footer(
      "Runs calibration and reconstruction first, as `process` does (a tilted camera's relief\n"
      "registration, a finer grid where the camera resolves one, bands past --max-memory). Writes\n"
      "DIR/maps/<parameter>.exr for every measured parameter (roughness, specular, ...; base_color\n"
      "linear RGB) and DIR/fit.json. Parameters the capture does not constrain get no map: fit.json\n"
      "says why. A measured parameter the fit's own evidence does not trust is marked UNRELIABLE,\n"
      "with the reason (fit.json: \"reliable\": false).");
  return std::function<int()>([args] {
    StageOptions stages = OptionsForPreset(ParsePreset(args->preset));
    if (args->dpi > 0.0) stages.calibration.dpi = args->dpi;
    if (!args->fit_mode.empty()) stages.fit.mode = fitting::ParseFitMode(args->fit_mode);
    stages.follow_fibres = args->follow_fibres;
    if (args->one_pixel_prior) stages.fit.pixel_prior_from_samples = false;
    if (args->normal_then_lobe) stages.fit.refine_normal_with_lobe = false;
    SetDecodeCacheBudget(args->run.max_memory_gib, &stages);
    SideRunOptions run_options = args->run;
    run_options.hold_out_lights = SplitLightIds(args->hold_out_lights);
    RunReport report;
    ProgressBar bar(false);
    PreparedCapture prepared = PrepareCapture(args->capture, stages, &report, bar.Callback());
    const SideRun run = RunSide(prepared, args->side, stages, run_options, &report, bar.Callback());
    const fitting::FitResult& fit = run.fit;
    bar.Finish();
    std::vector<std::pair<std::string, Image>> maps{{"base_color.exr", fit.base_color}};
    for (int p = 0; p < fitting::kFitParameterCount; ++p) {
      maps.emplace_back(std::string(fitting::FitParameterName(p)) + ".exr", fit.parameter_maps[p]);
    }
    if (!fit.anisotropy_rotation_deg.empty()) maps.emplace_back("anisotropy_rotation.exr", fit.anisotropy_rotation_deg);
    nlohmann::ordered_json fit_json = pipeline::FitResultToJson(fit);
    // What ran before the fit (the report's steps say more): the finer grid's factor and the bands.
    fit_json["run"] = {{"side", args->side}, {"ps_supersample", run.ps_supersample}, {"bands", run.plan.bands}};
    if (run.held_out) fit_json["held_out_lights"] = HeldOutCheckToJson(*run.held_out);
    WriteStageOutputs(args->out, maps, {{"fit.json", fit_json.dump(2) + "\n"}});
    for (int p = 0; p < fitting::kFitParameterCount; ++p) {
      const auto& decision = fit.maps[p];
      std::cout << "  " << fitting::FitParameterName(p) << ": "
                << (!decision.measured ? "not measured" : decision.constant ? "constant" : "map") << " "
                << decision.value << (decision.reason.empty() ? "" : " (" + decision.reason + ")")
                << (decision.measured && !decision.reliable ? " UNRELIABLE: " + decision.unreliable_reason : "") << "\n";
    }
    const auto& turn = fit.rotation_report;
    std::cout << "  anisotropy_rotation: " << (!turn.measured ? "not measured" : turn.constant ? "constant" : "map") << " "
              << turn.value << " deg" << (turn.reason.empty() ? "" : " (" + turn.reason + ")") << "\n";
    PrintSteps(report);
    std::cout << "maps and fit.json in " << args->out << "\n";
    return kExitOk;
  });
});

}  // namespace
}  // namespace u3mscan::cli
