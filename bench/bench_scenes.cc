#include "bench/bench_scenes.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace u3mscan::bench {

namespace {

struct Yarn {
  float r, g, b, roughness, specular, sheen, sheen_tint;
};

// Deterministic per-thread jitter in [-1, 1] from an integer thread index and the seed.
double Jitter(std::int64_t index, std::uint64_t seed) {
  std::uint64_t x = static_cast<std::uint64_t>(index) * 0x9E3779B97F4A7C15ull ^ (seed + 0x632BE59BD9B4E019ull);
  x ^= x >> 31;
  x *= 0xBF58476D1CE4E5B9ull;
  x ^= x >> 29;
  return static_cast<double>(x >> 11) / static_cast<double>(1ull << 53) * 2.0 - 1.0;
}

}  // namespace

std::vector<std::string> BenchSceneNames() { return {"plain", "satin", "velvet", "lace"}; }

synthetic::SceneTruth MakeBenchScene(const std::string& name, int width, int height, double pitch_mm,
                                     std::uint64_t seed) {
  const auto names = BenchSceneNames();
  if (std::find(names.begin(), names.end(), name) == names.end()) {
    throw std::invalid_argument("MakeBenchScene: unknown scene '" + name + "'");
  }
  synthetic::SceneTruth s;
  s.name = name;
  s.pitch_mm = pitch_mm;
  auto plane = [&](int channels, float value) { return Image(width, height, channels, value, pitch_mm); };
  s.height_mm = plane(1, 0.0f);
  s.normal = plane(3, 0.0f);
  s.base_color = plane(3, 0.0f);
  s.roughness = plane(1, 0.5f);
  s.specular = plane(1, 0.5f);
  s.specular_tint = plane(1, 0.0f);
  s.sheen = plane(1, 0.0f);
  s.sheen_tint = plane(1, 0.0f);
  s.metallic = plane(1, 0.0f);
  s.anisotropic = plane(1, 0.0f);
  s.alpha = plane(1, 1.0f);

  // Thread period of at least 12 pixels, so the weave is resolved on tiny grids too; slopes up to
  // about 25 deg (crown height 0.07 period), as on a plain weave under a loupe.
  const double period_mm = std::max(12.0 * pitch_mm, 0.5);
  const double k = 2.0 * M_PI / period_mm;
  const Yarn warp{0.55f, 0.42f, 0.30f, 0.75f, 0.4f, 0.0f, 0.0f};
  const Yarn weft{0.25f, 0.35f, 0.55f, 0.70f, 0.4f, 0.0f, 0.0f};
  const Yarn satin{0.70f, 0.62f, 0.45f, 0.35f, 0.7f, 0.0f, 0.0f};
  const Yarn velvet{0.45f, 0.08f, 0.10f, 0.90f, 0.3f, 0.8f, 0.5f};

  for (int row = 0; row < height; ++row) {
    for (int col = 0; col < width; ++col) {
      const double x = (col + 0.5) * pitch_mm, y = -(row + 0.5) * pitch_mm;
      double h = 0.0, dhdx = 0.0, dhdy = 0.0;
      Yarn yarn = warp;
      float alpha = 1.0f;
      if (name == "plain" || name == "lace") {
        // Basket: warp crowns where sin(kx) sin(ky) > 0, weft crowns elsewhere.
        const double a = 0.07 * period_mm;
        h = a * std::sin(k * x) * std::sin(k * y);
        dhdx = a * k * std::cos(k * x) * std::sin(k * y);
        dhdy = a * k * std::sin(k * x) * std::cos(k * y);
        yarn = std::sin(k * x) * std::sin(k * y) > 0 ? warp : weft;
        if (name == "lace") {
          // Round holes on a lattice of 3 periods, radius 0.6 period.
          const double cell = 3.0 * period_mm;
          const double cx = x - (std::floor(x / cell) + 0.5) * cell, cy = y - (std::floor(y / cell) + 0.5) * cell;
          if (cx * cx + cy * cy < 0.36 * period_mm * period_mm) alpha = 0.0f;
        }
      } else if (name == "satin") {
        // Floats along x: ridges across y, gently modulated along x every 4 periods.
        const double a = 0.06 * period_mm;
        const double kx = k / 4.0;
        h = a * std::sin(k * y) * (0.8 + 0.2 * std::cos(kx * x));
        dhdx = -a * std::sin(k * y) * 0.2 * kx * std::sin(kx * x);
        dhdy = a * k * std::cos(k * y) * (0.8 + 0.2 * std::cos(kx * x));
        yarn = satin;
      } else {  // velvet: pile tufts
        const double a = 0.03 * period_mm;
        const double kp = 2.0 * k;
        h = a * std::cos(kp * x) * std::cos(kp * y);
        dhdx = -a * kp * std::sin(kp * x) * std::cos(kp * y);
        dhdy = -a * kp * std::cos(kp * x) * std::sin(kp * y);
        yarn = velvet;
      }
      // Per-thread colour jitter (+-4 %), so base colour is a texture, not a constant.
      const std::int64_t thread = static_cast<std::int64_t>(std::floor(y / period_mm)) * 4099 +
                                  static_cast<std::int64_t>(std::floor(x / period_mm));
      const float jitter = static_cast<float>(1.0 + 0.04 * Jitter(thread, seed));
      const double norm = std::sqrt(dhdx * dhdx + dhdy * dhdy + 1.0);
      s.height_mm.at(0, row, col) = static_cast<float>(h);
      s.normal.at(0, row, col) = static_cast<float>(-dhdx / norm);
      s.normal.at(1, row, col) = static_cast<float>(-dhdy / norm);
      s.normal.at(2, row, col) = static_cast<float>(1.0 / norm);
      s.base_color.at(0, row, col) = std::min(1.0f, yarn.r * jitter);
      s.base_color.at(1, row, col) = std::min(1.0f, yarn.g * jitter);
      s.base_color.at(2, row, col) = std::min(1.0f, yarn.b * jitter);
      s.roughness.at(0, row, col) = yarn.roughness;
      s.specular.at(0, row, col) = yarn.specular;
      s.sheen.at(0, row, col) = yarn.sheen;
      s.sheen_tint.at(0, row, col) = yarn.sheen_tint;
      s.alpha.at(0, row, col) = alpha;
    }
  }
  return s;
}

}  // namespace u3mscan::bench
