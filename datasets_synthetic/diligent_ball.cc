// The DiLiGenT-format ball (diligent_ball.h): render, add the sensor's noise, write the folder.
#include "datasets_synthetic/diligent_ball.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>

#include "core/error.h"
#include "core/image.h"
#include "core/principled_brdf.h"
#include "core/text_file.h"
#include "core/units.h"
#include "datasets_synthetic/atomic_folder.h"
#include "u3m/image_io.h"

namespace u3mscan::synthetic {
namespace fs = std::filesystem;

namespace {

// Lights on a golden-angle spiral over the cap between the two polar angles (from +z, the
// camera's axis), evenly spread in solid angle.
std::vector<Eigen::Vector3d> SpiralLights(const DiLiGenTBallOptions& o) {
  const double golden_angle = kPi * (3.0 - std::sqrt(5.0));
  const double z_high = std::cos(DegToRad(o.min_light_polar_deg));
  const double z_low = std::cos(DegToRad(o.max_light_polar_deg));
  std::vector<Eigen::Vector3d> lights;
  for (int k = 0; k < o.lights; ++k) {
    const double z = o.lights == 1 ? z_high : z_high + (z_low - z_high) * k / (o.lights - 1.0);
    const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
    lights.emplace_back(r * std::cos(golden_angle * k), r * std::sin(golden_angle * k), z);
  }
  return lights;
}

// Any unit vector perpendicular to n (the BRDF is isotropic here: anisotropic = 0).
Eigen::Vector3d Perpendicular(const Eigen::Vector3d& n) {
  const Eigen::Vector3d helper = std::abs(n.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  return n.cross(helper).normalized();
}

std::string Triple(const Eigen::Vector3d& v) {
  char line[96];
  std::snprintf(line, sizeof line, "%.9g %.9g %.9g\n", v.x(), v.y(), v.z());
  return line;
}

}  // namespace

void DiLiGenTBallOptions::Check() const {
  constexpr int kMinSide = 16, kMaxSide = 1 << 14;
  if (width < kMinSide || height < kMinSide || width > kMaxSide || height > kMaxSide) {
    throw InputError("--size", "", "WxH with each side in [16, 16384]");
  }
  if (!(radius_px >= 4.0) || 2.0 * radius_px > std::min(width, height)) {
    throw InputError("--radius", "", "a ball radius of at least 4 px that fits the image (at most half its smaller side)");
  }
  if (lights < 3 || lights > 999) throw InputError("--lights", "", "3 to 999 lights (file names 001.png ...)");
  if (!(min_light_polar_deg >= 0.0 && min_light_polar_deg <= max_light_polar_deg && max_light_polar_deg < 90.0)) {
    throw InputError("light polar angles", "", "0 <= min <= max < 90 deg");
  }
  if (!(intensity_spread >= 0.0 && intensity_spread < 1.0)) throw InputError("intensity spread", "", "a value in [0, 1)");
  if (!(roughness >= 0.0 && roughness <= 1.0)) throw InputError("--roughness", "", "a value in [0, 1]");
  if (!(specular >= 0.0 && specular <= 1.0)) throw InputError("--specular", "", "a value in [0, 1]");
  if (!((base_color.array() >= 0.0).all() && (base_color.array() <= 1.0).all())) throw InputError("base colour", "", "values in [0, 1]");
  if (!(exposure > 0.0)) throw InputError("--exposure", "", "a positive exposure");
  if (!(read_noise >= 0.0 && full_well_electrons > 0.0)) throw InputError("noise", "", "read noise >= 0 and a positive full well");
}

DiLiGenTBall WriteDiLiGenTBall(const fs::path& dir, const DiLiGenTBallOptions& o) {
  o.Check();
  DiLiGenTBall ball;
  ball.light_directions = SpiralLights(o);
  std::mt19937_64 rng(o.seed);
  std::uniform_real_distribution<double> spread(1.0 - o.intensity_spread, 1.0 + o.intensity_spread);
  for (int k = 0; k < o.lights; ++k) ball.light_intensities.emplace_back(spread(rng), spread(rng), spread(rng));

  // The ball's normals (DiLiGenT frame: y up, so a row below the centre has y < 0), a tangent of
  // each (the BRDF's local frame, made once a pixel, not once a light) and its mask.
  const int w = o.width, h = o.height;
  const double cx = 0.5 * w, cy = 0.5 * h;
  std::vector<Eigen::Vector3d> normal(static_cast<std::size_t>(w) * h, Eigen::Vector3d::Zero());
  std::vector<Eigen::Vector3d> tangent(normal.size(), Eigen::Vector3d::Zero());
  Image mask(w, h, 1);
  for (int row = 0; row < h; ++row) {
    for (int col = 0; col < w; ++col) {
      const double x = (col + 0.5 - cx) / o.radius_px, y = -(row + 0.5 - cy) / o.radius_px;
      const double r2 = x * x + y * y;
      if (r2 >= 1.0) continue;
      const std::size_t i = static_cast<std::size_t>(row) * w + col;
      normal[i] = Eigen::Vector3d(x, y, std::sqrt(1.0 - r2));
      tangent[i] = Perpendicular(normal[i]);
      mask.at(0, row, col) = 1.0f;
      ++ball.object_pixels;
    }
  }

  PrincipledParams<double> params;
  params.base_color = o.base_color;
  params.roughness = o.roughness;
  params.specular = o.specular;
  std::normal_distribution<double> gaussian(0.0, 1.0);
  WriteFolderAtomically(dir, [&](const fs::path& staging) {
    std::string filenames;
    for (int k = 0; k < o.lights; ++k) {
      const Eigen::Vector3d& l = ball.light_directions[k];
      const Eigen::Vector3d& e = ball.light_intensities[k];
      Image frame(w, h, 3);
      for (int row = 0; row < h; ++row) {
        for (int col = 0; col < w; ++col) {
          const std::size_t i = static_cast<std::size_t>(row) * w + col;
          Eigen::Vector3d rgb = Eigen::Vector3d::Zero();
          const Eigen::Vector3d& n = normal[i];
          if (n.z() > 0.0 && n.dot(l) > 0.0) {
            // Local frame: z = the normal; the camera looks down -z, so the view is +z.
            const Eigen::Vector3d& t = tangent[i];
            const Eigen::Vector3d b = n.cross(t);
            const Eigen::Vector3d l_local(t.dot(l), b.dot(l), n.dot(l)), v_local(t.z(), b.z(), n.z());
            rgb = (EvaluatePrincipled(params, l_local, v_local) * (kPi * o.exposure * n.dot(l))).cwiseProduct(e);
          }
          bool clipped = false;
          for (int c = 0; c < 3; ++c) {
            double value = rgb(c);
            if (o.noise) {
              const double sigma = std::sqrt(o.read_noise * o.read_noise + std::max(0.0, value) / o.full_well_electrons);
              value += sigma * gaussian(rng);
            }
            clipped = clipped || value >= 1.0;
            frame.at(c, row, col) = static_cast<float>(std::clamp(value, 0.0, 1.0));
          }
          if (clipped && mask.at(0, row, col) > 0.0f) ++ball.saturated_observations;
        }
      }
      char name[16];
      std::snprintf(name, sizeof name, "%03d.png", k + 1);
      WriteImageFile(frame, staging / name, ImageWriteOptions{SampleFormat::kUInt16, PixelEncoding::kLinear});
      filenames += std::string(name) + "\n";
    }
    WriteImageFile(mask, staging / "mask.png", ImageWriteOptions{SampleFormat::kUInt8, PixelEncoding::kLinear});

    std::string directions, intensities, normals;
    for (int k = 0; k < o.lights; ++k) {
      directions += Triple(ball.light_directions[k]);
      intensities += Triple(ball.light_intensities[k]);
    }
    normals.reserve(normal.size() * 32);
    for (const Eigen::Vector3d& n : normal) normals += Triple(n);
    WriteTextFileAtomically(staging / "light_directions.txt", directions);
    WriteTextFileAtomically(staging / "light_intensities.txt", intensities);
    WriteTextFileAtomically(staging / "Normal_gt.txt", normals);
    WriteTextFileAtomically(staging / "filenames.txt", filenames);
  });
  return ball;
}

}  // namespace u3mscan::synthetic
