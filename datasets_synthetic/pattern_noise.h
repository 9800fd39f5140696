#pragma once
// Deterministic hashing and value noise for the scene patterns: a pure function of the seed and
// integer lattice coordinates, so a pattern is the same for any thread count, grid size or dpi.

#include <cmath>
#include <cstdint>

namespace u3mscan::synthetic::internal {

// SplitMix64 finaliser: a strong 64-bit mix (Steele et al. 2014), cheap enough per pixel.
inline std::uint64_t Mix64(std::uint64_t z) {
  z += 0x9e3779b97f4a7c15ull;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}

// Hash of a seed, a stream id (what the number is for) and up to two lattice coordinates.
inline std::uint64_t Hash(std::uint64_t seed, std::uint64_t stream, std::int64_t a, std::int64_t b = 0) {
  std::uint64_t h = Mix64(seed ^ Mix64(stream));
  h = Mix64(h ^ static_cast<std::uint64_t>(a));
  return Mix64(h ^ (static_cast<std::uint64_t>(b) * 0xd6e8feb86659fd93ull));
}

// Uniform in [0, 1) from 24 hash bits (exact in float).
inline float HashUnit(std::uint64_t seed, std::uint64_t stream, std::int64_t a, std::int64_t b = 0) {
  return static_cast<float>(Hash(seed, stream, a, b) >> 40) * (1.0f / 16777216.0f);
}

// Streams: one per use, so changing one pattern never shifts another's random numbers.
enum Stream : std::uint64_t {
  kWarpColor = 1, kWarpColor2, kWeftColor, kWeftColor2, kWarpSlub, kWeftSlub, kFibre, kPlyPhase,
  kPileTips, kPileCrush, kPileLean, kKnitColor, kKnitColor2, kKnitSlub, kLaceColor, kLaceColor2,
  kLaceSlub,
};

// Quintic fade (Perlin 2002): C2 continuous, so noise heights have continuous normals.
inline double Fade(double t) { return t * t * t * (t * (t * 6.0 - 15.0) + 10.0); }

// 1-D value noise in [-1, 1] with unit lattice spacing, one independent curve per `line`.
inline double ValueNoise1(std::uint64_t seed, std::uint64_t stream, std::int64_t line, double x) {
  const double fx = std::floor(x);
  const auto ix = static_cast<std::int64_t>(fx);
  const double t = Fade(x - fx);
  const double a = HashUnit(seed, stream, line, ix);
  const double b = HashUnit(seed, stream, line, ix + 1);
  return 2.0 * (a + (b - a) * t) - 1.0;
}

// 2-D value noise in [-1, 1] with unit lattice spacing.
inline double ValueNoise2(std::uint64_t seed, std::uint64_t stream, double x, double y) {
  const double fx = std::floor(x), fy = std::floor(y);
  const auto ix = static_cast<std::int64_t>(fx);
  const auto iy = static_cast<std::int64_t>(fy);
  const double tx = Fade(x - fx), ty = Fade(y - fy);
  const double v00 = HashUnit(seed, stream, ix, iy), v10 = HashUnit(seed, stream, ix + 1, iy);
  const double v01 = HashUnit(seed, stream, ix, iy + 1), v11 = HashUnit(seed, stream, ix + 1, iy + 1);
  const double top = v00 + (v10 - v00) * tx;
  const double bottom = v01 + (v11 - v01) * tx;
  return 2.0 * (top + (bottom - top) * ty) - 1.0;
}

// Sum of `octaves` value-noise octaves (lacunarity 2, gain 0.5), normalised to [-1, 1].
inline double Fbm2(std::uint64_t seed, std::uint64_t stream, double x, double y, int octaves) {
  double sum = 0.0, amplitude = 1.0, norm = 0.0;
  for (int o = 0; o < octaves; ++o) {
    sum += amplitude * ValueNoise2(seed, stream + 0x100u * static_cast<std::uint64_t>(o), x, y);
    norm += amplitude;
    amplitude *= 0.5;
    x *= 2.0;
    y *= 2.0;
  }
  return sum / norm;
}

}  // namespace u3mscan::synthetic::internal
