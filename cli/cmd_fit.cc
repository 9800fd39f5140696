// `u3mscan fit CAPTURE -o DIR`: everything up to the Principled fit of one side; writes the fitted
// parameter maps as float EXR and fit.json (per-cluster parameters, uncertainties, what was left
// out and why, run times).
#include <iostream>
#include <memory>

#include "cli/command.h"
#include "cli/progress_bar.h"
#include "cli/stage_outputs.h"
#include "pipeline/fit_json.h"
#include "pipeline/relief_registration.h"
#include "pipeline/stages.h"
#include "pipeline/view_parallax.h"

namespace u3mscan::cli {
namespace {

U3MSCAN_REGISTER_COMMAND(kFitCommand, "fit", "Capture -> fitted Principled parameter maps and fit.json", 50,
                         [](CLI::App& sub) {
  struct Args {
    std::string capture, out, side = "front", preset = "balanced", fit_mode;
    double dpi = 0.0;
    bool follow_fibres = false;
    bool one_pixel_prior = false;
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
  sub.add_flag("--follow-fibres", args->follow_fibres,
               "Turn the anisotropic stretch per pixel along the fibres the normals show, as `process "
               "--follow-fibres` does (docs/fitting.md, Fibre directions from the relief)");
  sub.add_flag("--one-pixel-prior", args->one_pixel_prior,
               "Regularise every pixel toward its cluster with one prior std (0.1), not with the spread each "
               "cluster's samples show (for comparisons; docs/fitting.md, Per-pixel spread from the samples)");
  sub.footer(
      "Runs calibration and reconstruction first. Writes DIR/maps/<parameter>.exr for every measured\n"
      "parameter (roughness, specular, ...; base_color linear RGB) and DIR/fit.json. Parameters the\n"
      "capture does not constrain get no map: fit.json says why. A measured parameter the fit's own\n"
      "evidence does not trust is marked UNRELIABLE, with the reason (fit.json: \"reliable\": false).");
  return std::function<int()>([args] {
    StageOptions stages = OptionsForPreset(ParsePreset(args->preset));
    if (args->dpi > 0.0) stages.calibration.dpi = args->dpi;
    if (!args->fit_mode.empty()) stages.fit.mode = fitting::ParseFitMode(args->fit_mode);
    stages.follow_fibres = args->follow_fibres;
    if (args->one_pixel_prior) stages.fit.pixel_prior_from_samples = false;
    RunReport report;
    ProgressBar bar(false);
    PreparedCapture prepared = PrepareCapture(args->capture, stages, &report, bar.Callback());
    Stack stack = BuildSideStack(prepared, args->side, stages, &report, bar.Callback());
    // Heights integrated along the camera's rays (pipeline/view_parallax.h); the frames lie on the plane.
    SetViewParallax(SideViews(prepared, args->side), prepared.calibration, /*rectified_on_relief=*/false, &stages);
    const SideReconstruction geometry = ReconstructSide(&stack, stages, Image(), &report, bar.Callback());
    const fitting::FitResult fit = FitSide(stack, geometry, stages, &report, bar.Callback());
    bar.Finish();
    std::vector<std::pair<std::string, Image>> maps{{"base_color.exr", fit.base_color}};
    for (int p = 0; p < fitting::kFitParameterCount; ++p) {
      maps.emplace_back(std::string(fitting::FitParameterName(p)) + ".exr", fit.parameter_maps[p]);
    }
    if (!fit.anisotropy_rotation_deg.empty()) maps.emplace_back("anisotropy_rotation.exr", fit.anisotropy_rotation_deg);
    WriteStageOutputs(args->out, maps, {{"fit.json", pipeline::FitResultToJson(fit).dump(2) + "\n"}});
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
