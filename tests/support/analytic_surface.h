#pragma once
// A height field given in closed form, z(x, y) with its slopes, and the unit normal map it has on
// a metric grid (reconstruction tests: integration, levelling). Lengths in millimetres; x right,
// y up, rows growing with -y; pixel (col, row) centred at ((col + 0.5) p, -(row + 0.5) p).
// Header only, needs nothing but core.

#include <cmath>
#include <functional>

#include "core/image.h"

namespace u3mscan::testing {

struct AnalyticSurface {
  std::function<double(double, double)> z;  // mm at (x, y) mm
  std::function<double(double, double)> dzdx;
  std::function<double(double, double)> dzdy;
};

inline double GridX(int col, double pitch_mm) { return (col + 0.5) * pitch_mm; }
inline double GridY(int row, double pitch_mm) { return -(row + 0.5) * pitch_mm; }  // rows grow with -y

// n = (-dz/dx, -dz/dy, 1) / |.| at every pixel centre; 3 channels, pitch `pitch_mm`.
inline Image NormalsOfSurface(const AnalyticSurface& s, int width, int height, double pitch_mm) {
  Image n(width, height, 3, 0.0f, pitch_mm);
  for (int r = 0; r < height; ++r)
    for (int c = 0; c < width; ++c) {
      const double gx = s.dzdx(GridX(c, pitch_mm), GridY(r, pitch_mm)), gy = s.dzdy(GridX(c, pitch_mm), GridY(r, pitch_mm));
      const double len = std::sqrt(gx * gx + gy * gy + 1.0);
      n.at(0, r, c) = static_cast<float>(-gx / len);
      n.at(1, r, c) = static_cast<float>(-gy / len);
      n.at(2, r, c) = static_cast<float>(1.0 / len);
    }
  return n;
}

}  // namespace u3mscan::testing
