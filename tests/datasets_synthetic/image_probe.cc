// Image comparison probe (not a test, not in ctest or the default build): prints per-channel
// statistics of images over a central crop and, for two images, their difference and correlation.
// Used to measure render contrast against truth (docs/synthetic-scanner.md).
// Build: cmake --build build --target synth_image_probe
// Run:   build/tests/datasets_synthetic/synth_image_probe A.exr [B.exr] [--crop N] [--shift DX DY]
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstdio>
#include <cstring>
#include <string>

#include "u3m/image_io.h"

using namespace u3mscan;

int main(int argc, char** argv) {
  std::string a_path, b_path;
  int crop = 0;
  double shift_x = 0.0, shift_y = 0.0;  // B is read at (col + shift_x, row + shift_y), bilinear
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--crop") && i + 1 < argc) {
      crop = std::atoi(argv[++i]);
    } else if (!std::strcmp(argv[i], "--shift") && i + 2 < argc) {
      shift_x = std::atof(argv[++i]);
      shift_y = std::atof(argv[++i]);
    } else if (a_path.empty()) {
      a_path = argv[i];
    } else {
      b_path = argv[i];
    }
  }
  if (a_path.empty()) {
    std::fprintf(stderr, "usage: synth_image_probe A [B] [--crop N]\n");
    return 2;
  }
  const Image a = ReadImageFile(a_path, PixelEncoding::kLinear);
  Image b;
  if (!b_path.empty()) b = ReadImageFile(b_path, PixelEncoding::kLinear);
  const int w = a.width(), h = a.height();
  const int n = crop > 0 ? std::min({crop, w, h}) : std::min(w, h);
  const int c0 = (w - n) / 2, r0 = (h - n) / 2;
  std::printf("%s %dx%dx%d crop %d at (%d,%d)\n", a_path.c_str(), w, h, a.channels(), n, c0, r0);
  for (int c = 0; c < a.channels(); ++c) {
    double sa = 0, saa = 0, sb = 0, sbb = 0, sab = 0, sd2 = 0;
    const int count = n * n;
    for (int r = r0; r < r0 + n; ++r)
      for (int col = c0; col < c0 + n; ++col) {
        const double x = a.at(c, r, col);
        sa += x, saa += x * x;
        if (!b.empty()) {
          const double fx = col + shift_x, fy = r + shift_y;
          const int x0 = std::clamp(static_cast<int>(std::floor(fx)), 0, w - 2), y0 = std::clamp(static_cast<int>(std::floor(fy)), 0, h - 2);
          const double ax = fx - x0, ay = fy - y0;
          const double y = (1 - ay) * ((1 - ax) * b.at(c, y0, x0) + ax * b.at(c, y0, x0 + 1)) +
                           ay * ((1 - ax) * b.at(c, y0 + 1, x0) + ax * b.at(c, y0 + 1, x0 + 1));
          sb += y, sbb += y * y, sab += x * y, sd2 += (x - y) * (x - y);
        }
      }
    const double ma = sa / count, va = saa / count - ma * ma;
    std::printf("  ch%d mean %.5f std %.5f", c, ma, std::sqrt(std::max(0.0, va)));
    if (!b.empty()) {
      const double mb = sb / count, vb = sbb / count - mb * mb, cov = sab / count - ma * mb;
      std::printf(" | B mean %.5f std %.5f | rms diff %.5f corr %.4f std ratio A/B %.4f", mb, std::sqrt(std::max(0.0, vb)),
                  std::sqrt(sd2 / count), cov / std::sqrt(va * vb), std::sqrt(va / vb));
    }
    std::printf("\n");
  }
  return 0;
}
