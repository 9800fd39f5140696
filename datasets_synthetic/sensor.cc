#include "datasets_synthetic/sensor.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "core/parallel.h"
#include "core/units.h"

namespace u3mscan::synthetic {
namespace {

// SplitMix64 finaliser: a counter-based generator, so pixel i's numbers need no shared state.
std::uint64_t Mix64(std::uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

// Uniform in (0, 1], never 0 so that log() in Box-Muller stays finite.
double Unit(std::uint64_t bits) { return (static_cast<double>(bits >> 11) + 1.0) * 0x1.0p-53; }

// Two independent standard normals for one (stream, index) pair (Box-Muller).
void Gaussians(std::uint64_t stream, std::uint64_t index, double* g0, double* g1) {
  const std::uint64_t a = Mix64(stream ^ Mix64(index));
  const std::uint64_t b = Mix64(a);
  const double r = std::sqrt(-2.0 * std::log(Unit(a)));
  const double phi = 2.0 * kPi * Unit(b);
  *g0 = r * std::cos(phi);
  *g1 = r * std::sin(phi);
}

}  // namespace

std::uint64_t FrameSeed(std::uint64_t rig_seed, std::string_view frame_name) {
  std::uint64_t h = 1469598103934665603ull;  // FNV-1a of the name, then mixed with the seed
  for (unsigned char c : frame_name) h = (h ^ c) * 1099511628211ull;
  return Mix64(h ^ Mix64(rig_seed));
}

RawFrame ExposeSensor(const Image& linear, const SensorSpec& sensor, std::uint64_t camera_seed,
                      std::uint64_t frame_seed, bool bayer) {
  if (linear.channels() != 1 && linear.channels() != 3) throw std::invalid_argument("ExposeSensor: 1 or 3 channels");
  if (sensor.bit_depth < 8 || sensor.bit_depth > 16 || !(sensor.white_level_dn > sensor.black_level_dn)) {
    throw std::invalid_argument("ExposeSensor: bad sensor levels");
  }
  RawFrame raw;
  raw.width = linear.width();
  raw.height = linear.height();
  raw.channels = bayer ? 1 : 3;
  const std::size_t n = linear.pixel_count();
  raw.dn.assign(n * raw.channels, 0);
  const double gain_dn = (sensor.white_level_dn - sensor.black_level_dn) / sensor.full_well_e;  // DN per electron
  const double max_dn = std::min(sensor.white_level_dn, std::ldexp(1.0, sensor.bit_depth) - 1.0);
  const std::uint64_t pattern_stream = Mix64(camera_seed ^ 0xD1B54A32D192ED03ull);
  ParallelFor(static_cast<std::size_t>(raw.height), [&](std::size_t begin, std::size_t end) {
    for (std::size_t row = begin; row < end; ++row) {
      for (int col = 0; col < raw.width; ++col) {
        const std::size_t i = row * raw.width + col;
        double pattern_dn = 0.0, unused;
        if (sensor.noise) {
          Gaussians(pattern_stream, i, &pattern_dn, &unused);
          pattern_dn *= sensor.fixed_pattern_dn;
        }
        for (int c = 0; c < raw.channels; ++c) {
          const int colour = bayer ? BayerChannel(static_cast<int>(row), col) : c;
          const int src = linear.channels() == 3 ? colour : 0;
          const double v = std::max(0.0, static_cast<double>(linear.plane(src)[i]));
          const double electrons = v * sensor.full_well_e;
          double shot = 0.0, read = 0.0;
          if (sensor.noise) Gaussians(frame_seed, i * 3 + c, &shot, &read);
          const double noisy_e = electrons + std::sqrt(electrons) * shot + sensor.read_noise_e * read;
          const double dn = sensor.black_level_dn + pattern_dn + noisy_e * gain_dn;
          raw.dn[static_cast<std::size_t>(c) * n + i] = static_cast<std::uint16_t>(std::clamp(std::round(dn), 0.0, max_dn));
        }
      }
    }
  });
  return raw;
}

Image RawToLinear(const RawFrame& raw, const SensorSpec& sensor) {
  Image out(raw.width, raw.height, raw.channels);
  const double scale = 1.0 / (sensor.white_level_dn - sensor.black_level_dn);
  for (std::size_t k = 0; k < raw.dn.size(); ++k) {
    out.data()[k] = static_cast<float>(std::max(0.0, (raw.dn[k] - sensor.black_level_dn) * scale));
  }
  return out;
}

double NoiseSigma(const SensorSpec& sensor, double v) {
  const double range_dn = sensor.white_level_dn - sensor.black_level_dn;
  const double electrons = std::max(0.0, v) * sensor.full_well_e;
  const double sigma_e2 = sensor.noise ? electrons + sensor.read_noise_e * sensor.read_noise_e : 0.0;
  const double pattern_dn2 = sensor.noise ? sensor.fixed_pattern_dn * sensor.fixed_pattern_dn : 0.0;
  const double sigma_dn2 = sigma_e2 * std::pow(range_dn / sensor.full_well_e, 2) + pattern_dn2 + 1.0 / 12.0;
  return std::sqrt(sigma_dn2) / range_dn;
}

}  // namespace u3mscan::synthetic
