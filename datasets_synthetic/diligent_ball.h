#pragma once
// A glossy ball written in the folder format of the DiLiGenT photometric-stereo benchmark (Shi et
// al., "A Benchmark Dataset and Evaluation for Non-Lambertian and Uncalibrated Photometric
// Stereo", CVPR 2016), which `u3mscan bench --diligent` reads (bench/diligent.h). It lets the
// reader and the benchmark be tested where the real data set is not (it is not in the repository
// and nothing is downloaded), and gives a ball whose truth is exact.
//
// The folder (one object):
//   filenames.txt          one image file name per line, in light order (001.png ...)
//   001.png ...            16-bit linear RGB, orthographic camera looking down -z
//   light_directions.txt   one "x y z" per line: unit vector toward the light
//   light_intensities.txt  one "r g b" per line: the light's relative intensity per channel
//   mask.png               8-bit, non-zero on the object
//   Normal_gt.txt          width x height lines "nx ny nz" in row-major order, 0 0 0 off the object
// Frame (DiLiGenT's): x to the right of the image, y up, z toward the camera.
//
// The ball is rendered with the Principled BRDF (core/principled_brdf.h), point-sampled at each
// pixel's centre (no cast shadows on a convex ball), with shot and read noise, 16-bit quantised
// and clipped at full scale, as a camera would: the highlights of the brightest lights saturate.

#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace u3mscan::synthetic {

struct DiLiGenTBallOptions {
  int width = 612;  // DiLiGenT's image size
  int height = 512;
  double radius_px = 200.0;  // the ball's radius on the image; centred
  int lights = 96;           // DiLiGenT's count
  // Lights on a spiral over the cap within max_light_polar_deg of the view axis (DiLiGenT's reach
  // about 55 deg from the camera).
  double min_light_polar_deg = 5.0;
  double max_light_polar_deg = 55.0;
  // Each light's intensity per channel is 1 +- this (uniform), written to light_intensities.txt.
  double intensity_spread = 0.2;
  // The material: Principled parameters (the rest at 0): a glossy ball.
  Eigen::Vector3d base_color{0.45, 0.25, 0.12};
  double roughness = 0.25;
  double specular = 0.5;
  // Full scale = 1: a white Lambertian facet facing a light of intensity 1 reads this.
  double exposure = 0.6;
  bool noise = true;
  double read_noise = 3e-4;           // std, fraction of full scale
  double full_well_electrons = 3e4;   // shot noise: std sqrt(value / full well)
  std::uint64_t seed = 1;

  // Throws InputError naming the `u3mscan synth-ball` option (--size, --radius, --lights, ...) of a
  // value out of range.
  void Check() const;
};

struct DiLiGenTBall {
  std::vector<Eigen::Vector3d> light_directions;   // unit, toward the light
  std::vector<Eigen::Vector3d> light_intensities;  // per channel
  long long object_pixels = 0;                     // non-zero in mask.png
  long long saturated_observations = 0;            // object pixels clipped at full scale in some channel
};

// Renders the ball and writes the folder `dir`, which must not exist or be empty; written whole or
// not at all (atomic_folder.h). Throws InputError for options that fail Check(), naming dir when
// it cannot be used and naming the file when one cannot be written.
DiLiGenTBall WriteDiLiGenTBall(const std::filesystem::path& dir, const DiLiGenTBallOptions& options);

}  // namespace u3mscan::synthetic
