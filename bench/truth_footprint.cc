#include "bench/truth_footprint.h"

#include <algorithm>
#include <cmath>

namespace u3mscan::bench {
namespace {

// A truth pixel is fabric when its alpha is at least this (holes are 0, fabric 1).
constexpr float kFabricAlpha = 0.5f;
// Grids whose pitches differ by less than this (relative) are the same resolution: bilinear.
constexpr double kSamePitch = 1e-6;
// Slack (truth px) when testing whether a position lies on the truth grid: float round-off.
constexpr double kEdgeSlackPx = 1e-6;

// Length of [a0, a1] inside [b0, b1].
double Overlap(double a0, double a1, double b0, double b1) { return std::max(0.0, std::min(a1, b1) - std::max(a0, b0)); }

}  // namespace

TruthFootprint::TruthFootprint(const TruthMaps& truth, double x0_mm, double y1_mm, double pitch_mm)
    : truth_(truth), x0_mm_(x0_mm), y1_mm_(y1_mm), pitch_mm_(pitch_mm) {
  area_ = pitch_mm > truth.pitch_mm * (1.0 + kSamePitch);
}

bool TruthFootprint::Gather(int col, int row, std::vector<TruthTap>* taps) const {
  taps->clear();
  const int tw = truth_.normal.width(), th = truth_.normal.height();
  const double tp = truth_.pitch_mm;
  auto fabric = [&](int c, int r) { return truth_.alpha.empty() || truth_.alpha.at(0, r, c) >= kFabricAlpha; };
  if (!area_) {
    // Bilinear: the output centre in truth pixel-centre coordinates.
    const double x = x0_mm_ + (col + 0.5) * pitch_mm_, y = y1_mm_ - (row + 0.5) * pitch_mm_;
    const double u = (x - truth_.x0_mm) / tp - 0.5, v = (truth_.y1_mm - y) / tp - 0.5;
    if (!(u >= -kEdgeSlackPx && v >= -kEdgeSlackPx && u <= tw - 1 + kEdgeSlackPx && v <= th - 1 + kEdgeSlackPx)) return false;
    const int c0 = std::clamp(static_cast<int>(std::floor(u)), 0, tw - 1), r0 = std::clamp(static_cast<int>(std::floor(v)), 0, th - 1);
    const int c1 = std::min(c0 + 1, tw - 1), r1 = std::min(r0 + 1, th - 1);
    const float fx = static_cast<float>(std::clamp(u - c0, 0.0, 1.0)), fy = static_cast<float>(std::clamp(v - r0, 0.0, 1.0));
    // All four neighbours must be fabric, even one of weight 0 (the interpolated truth would mix a hole in).
    for (int rr : {r0, r1}) {
      for (int cc : {c0, c1}) {
        if (!fabric(cc, rr)) return false;
      }
    }
    taps->push_back({c0, r0, (1 - fx) * (1 - fy)});
    taps->push_back({c1, r0, fx * (1 - fy)});
    taps->push_back({c0, r1, (1 - fx) * fy});
    taps->push_back({c1, r1, fx * fy});
    return true;
  }
  // Footprint in truth pixel-edge coordinates: truth pixel i covers [i, i + 1].
  const double u0 = (x0_mm_ + col * pitch_mm_ - truth_.x0_mm) / tp, u1 = u0 + pitch_mm_ / tp;
  const double v0 = (truth_.y1_mm - (y1_mm_ - row * pitch_mm_)) / tp, v1 = v0 + pitch_mm_ / tp;
  if (!(u0 >= -kEdgeSlackPx && v0 >= -kEdgeSlackPx && u1 <= tw + kEdgeSlackPx && v1 <= th + kEdgeSlackPx)) return false;
  const int c_lo = std::max(0, static_cast<int>(std::floor(u0))), c_hi = std::min(tw - 1, static_cast<int>(std::ceil(u1)) - 1);
  const int r_lo = std::max(0, static_cast<int>(std::floor(v0))), r_hi = std::min(th - 1, static_cast<int>(std::ceil(v1)) - 1);
  double total = 0.0;
  for (int r = r_lo; r <= r_hi; ++r) {
    const double wy = Overlap(v0, v1, r, r + 1.0);
    if (wy <= 0.0) continue;
    for (int c = c_lo; c <= c_hi; ++c) {
      const double wx = Overlap(u0, u1, c, c + 1.0);
      if (wx <= 0.0) continue;
      if (!fabric(c, r)) return false;
      taps->push_back({c, r, static_cast<float>(wx * wy)});
      total += wx * wy;
    }
  }
  if (!(total > 0.0)) return false;
  for (TruthTap& t : *taps) t.weight = static_cast<float>(t.weight / total);
  return true;
}

float TapMean(const Image& image, int channel, const std::vector<TruthTap>& taps) {
  float sum = 0.0f;
  for (const TruthTap& t : taps) sum += t.weight * image.at(channel, t.row, t.col);
  return sum;
}

}  // namespace u3mscan::bench
