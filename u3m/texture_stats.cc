#include "u3m/texture_stats.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

#include "core/parallel.h"

namespace u3mscan {
namespace {

// Sums `per_pixel(row, col) -> array<double, 3>` over the image, rows in parallel; one partial sum
// per row keeps the result independent of the thread count.
template <typename F>
std::array<double, 3> SumOverPixels(const Image& image, F per_pixel) {
  const int h = image.height(), w = image.width();
  std::vector<std::array<double, 3>> rows(static_cast<std::size_t>(h), {0.0, 0.0, 0.0});
  ParallelFor(static_cast<std::size_t>(h), [&](std::size_t begin, std::size_t end) {
    for (std::size_t row = begin; row < end; ++row) {
      std::array<double, 3> sum{0.0, 0.0, 0.0};
      for (int col = 0; col < w; ++col) {
        const std::array<double, 3> v = per_pixel(static_cast<int>(row), col);
        sum[0] += v[0];
        sum[1] += v[1];
        sum[2] += v[2];
      }
      rows[row] = sum;
    }
  });
  std::array<double, 3> total{0.0, 0.0, 0.0};
  for (const auto& r : rows)
    for (int k = 0; k < 3; ++k) total[k] += r[k];
  return total;
}

int ColourChannels(const Image& image) { return image.channels() >= 3 ? 3 : 1; }

}  // namespace

double Blend(BlendMode mode, double i, double f) {
  switch (mode) {
    case BlendMode::kAdd: return i + f;
    case BlendMode::kSubtract: return i - f;
    case BlendMode::kMultiply: return i * f;
    case BlendMode::kDivide: return f > 1e-12 ? i / f : 1.0;  // x / 0 saturates
    case BlendMode::kMax: return std::max(i, f);
    case BlendMode::kMin: return std::min(i, f);
    case BlendMode::kOverlay: return i < 0.5 ? 2.0 * i * f : 1.0 - 2.0 * (1.0 - i) * (1.0 - f);  // image = base layer
  }
  return i * f;
}

double ScalarTextureMean(const Image& image, double factor, double offset) {
  if (image.empty()) return offset;
  const int n = ColourChannels(image);
  const auto sum = SumOverPixels(image, [&](int row, int col) {
    double v = 0.0;
    for (int c = 0; c < n; ++c) v += image.at(c, row, col);
    return std::array<double, 3>{v / n, 0.0, 0.0};
  });
  return offset + factor * sum[0] / static_cast<double>(image.pixel_count());
}

Rgb3 ColorTextureMean(const Image& image, BlendMode mode, const Rgb3& factor) {
  if (image.empty()) return factor;
  const bool rgb = ColourChannels(image) == 3;
  const auto sum = SumOverPixels(image, [&](int row, int col) {
    const double r = image.at(0, row, col);
    const double g = rgb ? image.at(1, row, col) : r;
    const double b = rgb ? image.at(2, row, col) : r;
    return std::array<double, 3>{std::clamp(Blend(mode, r, factor.r), 0.0, 1.0),
                                 std::clamp(Blend(mode, g, factor.g), 0.0, 1.0),
                                 std::clamp(Blend(mode, b, factor.b), 0.0, 1.0)};
  });
  const double count = static_cast<double>(image.pixel_count());
  return Rgb3{sum[0] / count, sum[1] / count, sum[2] / count};
}

Vec3 NormalTextureMean(const Image& image, double scale) {
  if (image.empty() || image.channels() < 3) return Vec3{};
  const auto sum = SumOverPixels(image, [&](int row, int col) {
    double x = (2.0 * image.at(0, row, col) - 1.0) * scale;
    double y = (2.0 * image.at(1, row, col) - 1.0) * scale;
    double z = 2.0 * image.at(2, row, col) - 1.0;
    const double length = std::sqrt(x * x + y * y + z * z);
    if (length < 1e-12) return std::array<double, 3>{0.0, 0.0, 0.0};  // a black pixel carries no direction
    return std::array<double, 3>{x / length, y / length, z / length};
  });
  const double length = std::sqrt(sum[0] * sum[0] + sum[1] * sum[1] + sum[2] * sum[2]);
  if (length < 1e-12) return Vec3{};
  return Vec3{sum[0] / length, sum[1] / length, sum[2] / length};
}

}  // namespace u3mscan
