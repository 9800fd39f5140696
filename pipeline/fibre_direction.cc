#include "pipeline/fibre_direction.h"

#include <Eigen/Core>
#include <cmath>
#include <stdexcept>

#include "core/parallel.h"
#include "fitting/shading_frame.h"
#include "pipeline/fine_grid.h"

namespace u3mscan {
namespace {

constexpr double kRadToDeg = 180.0 / M_PI;

// A normal map's value at (row, col) with the border clamped.
float Clamped(const Image& image, int channel, int row, int col) {
  row = std::clamp(row, 0, image.height() - 1);
  col = std::clamp(col, 0, image.width() - 1);
  return image.at(channel, row, col);
}

}  // namespace

Image FibreTurnFromNormals(const Image& normals, const FibreDirectionOptions& options) {
  if (normals.channels() != 3) throw std::invalid_argument("FibreTurnFromNormals: the normal map needs 3 channels");
  if (!options.Check()) throw std::invalid_argument("FibreTurnFromNormals: invalid options");
  const int w = normals.width(), h = normals.height();
  Image turn(w, h, 1, 0.0f, normals.pitch_mm());
  if (w == 0 || h == 0) return turn;

  // The tensor's three entries per pixel, in world axes (x right, y up: a row step is -y), from
  // central differences of every normal component (per pixel: the window's scale is in pixels).
  Image jxx(w, h, 1, 0.0f), jxy(w, h, 1, 0.0f), jyy(w, h, 1, 0.0f);
  ParallelFor(static_cast<std::size_t>(h), [&](std::size_t begin, std::size_t end) {
    for (auto row = static_cast<int>(begin); row < static_cast<int>(end); ++row) {
      for (int col = 0; col < w; ++col) {
        double xx = 0.0, xy = 0.0, yy = 0.0;
        for (int c = 0; c < 3; ++c) {
          const double gx = 0.5 * (Clamped(normals, c, row, col + 1) - Clamped(normals, c, row, col - 1));
          const double gy = -0.5 * (Clamped(normals, c, row + 1, col) - Clamped(normals, c, row - 1, col));
          if (!std::isfinite(gx) || !std::isfinite(gy)) continue;
          xx += gx * gx;
          xy += gx * gy;
          yy += gy * gy;
        }
        jxx.at(0, row, col) = static_cast<float>(xx);
        jxy.at(0, row, col) = static_cast<float>(xy);
        jyy.at(0, row, col) = static_cast<float>(yy);
      }
    }
  });
  jxx = GaussianBlurPlane(jxx, options.window_px);
  jxy = GaussianBlurPlane(jxy, options.window_px);
  jyy = GaussianBlurPlane(jyy, options.window_px);

  ParallelFor(static_cast<std::size_t>(h), [&](std::size_t begin, std::size_t end) {
    for (auto row = static_cast<int>(begin); row < static_cast<int>(end); ++row) {
      for (int col = 0; col < w; ++col) {
        const double a = jxx.at(0, row, col), b = jxy.at(0, row, col), d = jyy.at(0, row, col);
        const double trace = a + d;
        if (!(trace > options.min_trace)) continue;
        const double spread = std::sqrt((a - d) * (a - d) + 4.0 * b * b);
        if (spread / trace < options.min_coherence) continue;
        // The normal turns most along the angle 0.5 atan2(2b, a - d) in plan; the fibres run at
        // right angles to it.
        const double across = 0.5 * std::atan2(2.0 * b, a - d);
        const Eigen::Vector3d fibre_plan(-std::sin(across), std::cos(across), 0.0);
        Eigen::Vector3d n(normals.at(0, row, col), normals.at(1, row, col), normals.at(2, row, col));
        const double length = n.norm();
        if (!(length > 0.5 && length < 1.5)) continue;
        n /= length;
        // The fibres' direction in the tangent plane, as a turn from the unturned tangent.
        const Eigen::Vector3d fibre = fibre_plan - fibre_plan.dot(n) * n;
        if (fibre.squaredNorm() < 1e-12) continue;
        const Eigen::Vector3d t0 = fitting::MakeShadingFrame(n).tangent;
        const double deg = fitting::WrapHalfTurnDeg(std::atan2(n.dot(t0.cross(fibre)), t0.dot(fibre)) * kRadToDeg);
        turn.at(0, row, col) = static_cast<float>(deg);
      }
    }
  });
  return turn;
}

Image AverageTurnsOntoMaps(const Image& fine_turns, int k, double maps_pitch_mm) {
  if (k < 1 || fine_turns.channels() != 1 || fine_turns.width() % k != 0 || fine_turns.height() % k != 0) {
    throw std::invalid_argument("AverageTurnsOntoMaps: a 1-channel map whose sides are multiples of k >= 1");
  }
  const int w = fine_turns.width() / k, h = fine_turns.height() / k;
  Image out(w, h, 1, 0.0f, maps_pitch_mm);
  constexpr double kDegToDoubledRad = 2.0 * M_PI / 180.0;
  ParallelFor(static_cast<std::size_t>(h), [&](std::size_t begin, std::size_t end) {
    for (auto row = static_cast<int>(begin); row < static_cast<int>(end); ++row) {
      for (int col = 0; col < w; ++col) {
        double c = 0.0, s = 0.0;
        for (int j = 0; j < k; ++j) {
          for (int i = 0; i < k; ++i) {
            const double a = fine_turns.at(0, row * k + j, col * k + i) * kDegToDoubledRad;
            c += std::cos(a);
            s += std::sin(a);
          }
        }
        if (std::hypot(c, s) < 1e-6 * k * k) continue;
        out.at(0, row, col) = static_cast<float>(fitting::WrapHalfTurnDeg(0.5 * std::atan2(s, c) * kRadToDeg));
      }
    }
  });
  return out;
}

}  // namespace u3mscan
