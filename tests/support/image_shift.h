#pragma once
// Where one image holds what another holds: the sub-pixel shift between two images of the same
// pattern (two views of one light rectified onto one grid), for registration tests. Only plane 1
// (green) is compared; shading that differs smoothly between the images does not move the result.

#include <Eigen/Core>
#include <cmath>
#include <cstdint>

#include "core/image.h"

namespace u3mscan::testing {

struct PixelRect {
  int col0 = 0, row0 = 0, cols = 0, rows = 0;
};

// The central half of an image's grid.
inline PixelRect CentralHalf(const Image& image) {
  return {image.width() / 4, image.height() / 4, image.width() / 2, image.height() / 2};
}

// Normalised cross-correlation of plane 1 of `a` over `rect` with plane 1 of `b` moved by (dx, dy)
// whole pixels. 0 where the moved rectangle leaves `b`.
inline double Correlation(const Image& a, const Image& b, const PixelRect& rect, int dx, int dy) {
  if (rect.col0 + dx < 0 || rect.row0 + dy < 0 || rect.col0 + rect.cols + dx > b.width() ||
      rect.row0 + rect.rows + dy > b.height()) {
    return 0.0;
  }
  double sa = 0, sb = 0, saa = 0, sbb = 0, sab = 0;
  const double n = static_cast<double>(rect.cols) * rect.rows;
  for (int row = rect.row0; row < rect.row0 + rect.rows; ++row) {
    for (int col = rect.col0; col < rect.col0 + rect.cols; ++col) {
      const double u = a.at(1, row, col), v = b.at(1, row + dy, col + dx);
      sa += u, sb += v, saa += u * u, sbb += v * v, sab += u * v;
    }
  }
  const double cov = sab - sa * sb / n, va = saa - sa * sa / n, vb = sbb - sb * sb / n;
  return va > 0 && vb > 0 ? cov / std::sqrt(va * vb) : 0.0;
}

// Shift (px, x along columns, y along rows) at which `b` holds what `a` holds over `rect`: the
// best whole-pixel shift within +-reach, refined by a parabola through its neighbours on each axis.
inline Eigen::Vector2d ShiftPx(const Image& a, const Image& b, const PixelRect& rect, int reach = 10) {
  int best_x = 0, best_y = 0;
  double best = -2.0;
  for (int dy = -reach; dy <= reach; ++dy) {
    for (int dx = -reach; dx <= reach; ++dx) {
      const double c = Correlation(a, b, rect, dx, dy);
      if (c > best) best = c, best_x = dx, best_y = dy;
    }
  }
  auto vertex = [](double minus, double centre, double plus) {
    const double curvature = minus - 2.0 * centre + plus;
    return curvature < 0.0 ? 0.5 * (minus - plus) / curvature : 0.0;
  };
  return {best_x + vertex(Correlation(a, b, rect, best_x - 1, best_y), best, Correlation(a, b, rect, best_x + 1, best_y)),
          best_y + vertex(Correlation(a, b, rect, best_x, best_y - 1), best, Correlation(a, b, rect, best_x, best_y + 1))};
}

// Cells of one random albedo in [lo, hi] (a print with no period, grey), `cell_px` pixels a side,
// written into `base_color` (3 planes).
inline void PaintRandomPrint(Image* base_color, int cell_px, float lo, float hi) {
  for (int row = 0; row < base_color->height(); ++row) {
    for (int col = 0; col < base_color->width(); ++col) {
      std::uint32_t hash = static_cast<std::uint32_t>(row / cell_px) * 73856093u ^
                           static_cast<std::uint32_t>(col / cell_px) * 19349663u;
      hash = (hash ^ (hash >> 13)) * 0x5bd1e995u;
      const float albedo = lo + (hi - lo) * static_cast<float>((hash >> 8) & 0xffff) / 65535.0f;
      for (int c = 0; c < 3; ++c) base_color->at(c, row, col) = albedo;
    }
  }
}

}  // namespace u3mscan::testing
