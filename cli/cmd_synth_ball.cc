// `u3mscan synth-ball`: a glossy ball in the DiLiGenT folder format, for `u3mscan bench
// --diligent` where the real data set is not at hand (datasets_synthetic/diligent_ball.h).
#include <iostream>
#include <memory>
#include <string>

#include "cli/command.h"
#include "cli/size_option.h"
#include "core/error.h"
#include "datasets_synthetic/diligent_ball.h"

namespace u3mscan::cli {
namespace {

U3MSCAN_REGISTER_COMMAND(kSynthBallCommand, "synth-ball",
                         "Render a glossy ball in the DiLiGenT photometric-stereo folder format (for bench --diligent)", 510,
                         [](CLI::App& sub) {
  struct Args {
    synthetic::DiLiGenTBallOptions options;
    std::string size = "612x512";
    bool no_noise = false;
    std::string out;
  };
  auto args = std::make_shared<Args>();
  sub.add_option("--size", args->size, "Image size WxH in pixels (DiLiGenT's is 612x512)")->capture_default_str();
  sub.add_option("--radius", args->options.radius_px, "The ball's radius on the image, pixels")->capture_default_str();
  sub.add_option("--lights", args->options.lights, "Number of lights, on a spiral within 55 deg of the camera's axis")
      ->capture_default_str();
  sub.add_option("--roughness", args->options.roughness, "Principled roughness of the ball")->capture_default_str();
  sub.add_option("--specular", args->options.specular, "Principled specular of the ball (0: Burley's diffuse lobe alone)")
      ->capture_default_str();
  sub.add_option("--exposure", args->options.exposure,
                 "Full scale = 1: a white Lambertian facet facing a light of intensity 1 reads this (highlights above 1 clip)")
      ->capture_default_str();
  sub.add_option("--seed", args->options.seed, "Seed of the light intensities and the noise")->capture_default_str();
  sub.add_flag("--no-noise", args->no_noise, "No shot or read noise (only the 16-bit rounding and the clipping)");
  sub.add_option("-o,--output", args->out, "Output folder DIR (must not exist or be empty)")->required();
  return std::function<int()>([args] {
    ParseSizeOption(args->size, "612x512", &args->options.width, &args->options.height);
    args->options.noise = !args->no_noise;
    const synthetic::DiLiGenTBall ball = synthetic::WriteDiLiGenTBall(args->out, args->options);
    std::cout << ball.light_directions.size() << " images of a ball of " << ball.object_pixels << " px ("
              << ball.saturated_observations << " observations clipped) -> " << args->out << "\n";
    return kExitOk;
  });
});

}  // namespace
}  // namespace u3mscan::cli
