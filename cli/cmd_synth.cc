// `u3mscan synth`: the synthetic scanner. Renders a scene preset with a rig preset into a capture
// folder (DIR/capture) plus its ground truth (DIR/truth); see docs/synthetic-scanner.md.
#include <iostream>
#include <string>

#include "cli/command.h"
#include "cli/progress_bar.h"
#include "cli/size_option.h"
#include "core/logging.h"
#include "core/error.h"
#include "datasets_synthetic/synth_run.h"

namespace u3mscan::cli {
namespace {

U3MSCAN_REGISTER_COMMAND(kSynthCommand, "synth", "Render a synthetic capture folder with ground truth", 500,
                         [](CLI::App& sub) {
  struct Args {
    synthetic::SynthOptions options;
    std::string size = "64x64";
    std::string format = "dng";
    bool no_calibration = false;
    bool no_pose = false;
    bool no_thickness = false;
    bool no_noise = false;
    std::string calibration_roles = "all";
    std::string out;
  };
  auto args = std::make_shared<Args>();
  sub.add_option("--scene", args->options.scene, "Scene preset (plain, twill, satin, knit, denim, velvet, lace, ...)")->required();
  sub.add_option("--rig", args->options.rig, "Rig preset (distant, near, oblique, grazing, coplanar, single_light, noisy)")->required();
  sub.add_option("--size", args->size, "Camera frame size WxH in pixels (64x64 .. 7360x4912 and beyond)")->capture_default_str();
  sub.add_option("--lights", args->options.lights, "Number of lights on the rig's rings (0 = the rig's own count)")->capture_default_str();
  sub.add_option("--seed", args->options.seed, "Seed of scene, rig and noise")->capture_default_str();
  sub.add_option("--format", args->format, "Frame files: dng (Bayer RAW), tiff (16-bit RGB) or exr (float RGB)")->capture_default_str();
  sub.add_option("--dpi", args->options.dpi, "Ground resolution of the top camera and the scene grid")->capture_default_str();
  sub.add_option("--supersample", args->options.supersample,
                 "Rays per camera pixel along each axis (the pixel integrates light over its area; the scene is sampled "
                 "as many times finer, memory permitting, and the truth is its area average on the output grid). "
                 "0 = auto: 3 up to 1.5 MP, 2 up to 12 MP, 1 above")
      ->capture_default_str();
  sub.add_flag("--no-calibration", args->no_calibration, "Write sample and ambient frames only");
  sub.add_option("--calibration-frames", args->calibration_roles,
                 "Calibration roles to render, comma-separated: dark, flat, board, sphere, chart, backlight, or all "
                 "(dark,flat: a scanner whose geometry and colour the manifest gives, with a flat field per light)")
      ->capture_default_str();
  sub.add_flag("--no-pose", args->no_pose, "Leave camera poses out of capture.json (calibration finds them from the board)");
  sub.add_flag("--no-thickness", args->no_thickness,
               "Leave sample.thickness_mm out of capture.json (the maps are then made on the table plane z = 0, not "
               "on the sample's face)");
  sub.add_flag("--no-noise", args->no_noise,
               "Expose the frames without sensor noise (shot, read, fixed pattern; only the rounding to digital numbers): the "
               "same capture as without the flag, to measure what the noise costs");
  sub.add_option("-o,--output", args->out, "Output folder DIR (must not exist or be empty)")->required();
  return std::function<int()>([args] {
    ParseSizeOption(args->size, "64x64 or 7360x4912", &args->options.width, &args->options.height);
    const auto format = synthetic::FrameFormatFromName(args->format);
    if (!format) throw InputError("--format", "", "dng, tiff or exr, got '" + args->format + "'");
    args->options.capture.format = *format;
    args->options.capture.calibration_frames = !args->no_calibration;
    args->options.capture.calibration_roles =
        synthetic::CalibrationRolesFromList(args->calibration_roles, "--calibration-frames");
    args->options.capture.write_pose = !args->no_pose;
    args->options.capture.write_thickness = !args->no_thickness;
    args->options.sensor_noise = !args->no_noise;
    ProgressBar bar(GetLogLevel() > LogLevel::kInfo);
    args->options.capture.progress = bar.Callback();
    const synthetic::CaptureStats stats = synthetic::RunSynth(args->options, args->out);
    bar.Finish();
    std::cout << stats.frames << " frames, " << stats.megapixels_rendered << " MP rendered in " << stats.render_seconds
              << " s: " << stats.MegapixelsPerSecond() << " MP/s (" << stats.total_seconds << " s with writing) -> "
              << args->out << "\n";
    return kExitOk;
  });
});

}  // namespace
}  // namespace u3mscan::cli
