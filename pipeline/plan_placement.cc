#include "pipeline/plan_placement.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <vector>

#include "core/parallel.h"
#include "pipeline/fine_grid.h"
#include "pipeline/relief_registration.h"
#include "reconstruction/relief_levelling.h"

namespace u3mscan {

namespace {

// The heights' long wavelengths on the maps' grid (k fine pixels a side): the quadratic that fits
// the map pixels' mean heights (weighted by their valid share when `fine_valid` is given) plus the
// rest's Gaussian low-pass of kPlacementReliefSigmaMapPx.
Image SampleShapeOnMaps(const Image& fine_height_mm, const Image& fine_valid, int k) {
  const double map_pitch_mm = fine_height_mm.pitch_mm() * k;
  const Image heights = BlockMean(fine_height_mm, k, map_pitch_mm);
  Image relief = heights;
  reconstruction::LevelRelief(reconstruction::Levelling::kQuadratic, &relief, nullptr,
                              fine_valid.empty() ? Image() : BlockMean(fine_valid, k, map_pitch_mm));
  Image shape = GaussianBlurPlane(relief, kPlacementReliefSigmaMapPx);
  auto out = shape.plane(0);
  const auto all = heights.plane(0);
  const auto rest = relief.plane(0);
  for (std::size_t i = 0; i < out.size(); ++i) out[i] += all[i] - rest[i];  // + the quadratic
  return shape;
}

}  // namespace

PlanPlacement::PlanPlacement(const Image& fine_height_mm, const Image& fine_valid,
                             const reconstruction::ViewParallax& parallax, int k)
    : parallax_(parallax), fine_pitch_mm_(fine_height_mm.pitch_mm()), k_(std::max(1, k)) {
  if (!parallax.enabled || fine_height_mm.empty() || !(fine_pitch_mm_ > 0.0)) return;
  const double depth = parallax.camera_z_mm - parallax.plane_z_mm;
  if (!(depth > 0.0)) return;
  // The relief without the sample's shape: the integrated heights drift over the map (a bowl or a
  // tilt of tens of um, which the top's quantile would read as depth at the centre), and the
  // sample lies on the face's plane. A quadratic over the map (the drift's low orders) is taken
  // out whole, then what is left of the wavelengths longer than kPlacementReliefSigmaMapPx; a
  // fabric's own hollows narrower than that keep their depth. On the maps' grid, so that the
  // blur's kernel stays a few hundred pixels.
  below_face_mm_ = Image(fine_height_mm.width(), fine_height_mm.height(), 1, 0.0f, fine_pitch_mm_);
  const auto h = fine_height_mm.plane(0);
  auto z = below_face_mm_.plane(0);
  double finite_sum = 0.0;
  std::size_t finite = 0;
  for (float v : h) {
    if (std::isfinite(v)) finite_sum += v, ++finite;
  }
  if (finite == 0) {
    below_face_mm_ = Image();
    return;
  }
  for (std::size_t i = 0; i < z.size(); ++i) z[i] = std::isfinite(h[i]) ? h[i] : static_cast<float>(finite_sum / finite);
  const Image long_wavelengths = UpsampleLinear(SampleShapeOnMaps(below_face_mm_, fine_valid, k_), k_);
  for (std::size_t i = 0; i < z.size(); ++i) z[i] -= long_wavelengths.plane(0)[i];
  const double top = ReliefTopMm(below_face_mm_, fine_valid);
  if (!std::isfinite(top)) {
    below_face_mm_ = Image();
    return;
  }
  for (std::size_t i = 0; i < z.size(); ++i) z[i] = std::isfinite(h[i]) ? static_cast<float>(z[i] - top) : 0.0f;
  // The largest offset: at a corner of the grid, at the deepest point (kept at kMaxPlanOffsetMapPx).
  double deepest = 0.0;
  for (float v : z) deepest = std::max(deepest, std::abs(static_cast<double>(v)));
  double lean = 0.0;
  for (const double x : {parallax.x0_mm, parallax.x0_mm + fine_height_mm.width() * fine_pitch_mm_}) {
    for (const double y : {parallax.y1_mm, parallax.y1_mm - fine_height_mm.height() * fine_pitch_mm_}) {
      lean = std::max(lean, std::hypot(parallax.camera_x_mm - x, parallax.camera_y_mm - y) / depth);
    }
  }
  largest_offset_fine_px_ = std::min(deepest * lean / fine_pitch_mm_, kMaxPlanOffsetMapPx * k_);
  margin_fine_px_ = static_cast<int>(std::ceil(largest_offset_fine_px_));
}

void PlanPlacement::OffsetFinePx(int col, int row, float* d_col, float* d_row) const {
  *d_col = 0.0f, *d_row = 0.0f;
  if (!enabled()) return;
  const double x = parallax_.x0_mm + (col + 0.5) * fine_pitch_mm_;
  const double y = parallax_.y1_mm - (row + 0.5) * fine_pitch_mm_;
  const double depth = parallax_.camera_z_mm - parallax_.plane_z_mm;
  // x_s - x_g = (z - plane) t, t = (camera - x_g).xy / depth; rows grow with -y.
  const double below = below_face_mm_.at(0, row, col);
  const double limit = kMaxPlanOffsetMapPx * k_;
  *d_col = static_cast<float>(std::clamp(below * (parallax_.camera_x_mm - x) / depth / fine_pitch_mm_, -limit, limit));
  *d_row = static_cast<float>(std::clamp(-below * (parallax_.camera_y_mm - y) / depth / fine_pitch_mm_, -limit, limit));
}

std::string PlacementDetail(const PlanPlacement& placement, double fine_pitch_mm) {
  if (!placement.enabled()) return std::string();
  char detail[96];
  std::snprintf(detail, sizeof detail, "; fine pixels placed on the plan by their heights (up to %.1f um)",
                placement.largest_offset_fine_px() * fine_pitch_mm * 1e3);
  return detail;
}

Image PlacedWeightedMean(const Image& fine, const Image& weights, const PlanPlacement& placement, int k,
                         double pitch_mm) {
  if (!placement.enabled()) return BlockWeightedMean(fine, weights, k, pitch_mm);
  if (placement.k() != k || placement.width() != fine.width() || placement.height() != fine.height())
    throw std::invalid_argument("PlacedWeightedMean: the placement was made for another grid or factor");
  if (!weights.empty() && (weights.width() != fine.width() || weights.height() != fine.height() || weights.channels() != 1))
    throw std::invalid_argument("PlacedWeightedMean: weights must be one plane of the image's size");
  const int fw = fine.width(), fh = fine.height();
  const int w = fw / k, h = fh / k, channels = fine.channels();
  const int m = placement.margin_fine_px();
  Image out(w, h, channels, 0.0f, pitch_mm);
  ParallelFor(static_cast<std::size_t>(h), [&](std::size_t r0, std::size_t r1) {
    std::vector<double> sum(static_cast<std::size_t>(channels)), own(static_cast<std::size_t>(channels));
    for (std::size_t rr = r0; rr < r1; ++rr) {
      const int row = static_cast<int>(rr);
      for (int col = 0; col < w; ++col) {
        std::fill(sum.begin(), sum.end(), 0.0);
        std::fill(own.begin(), own.end(), 0.0);
        double total = 0.0, own_total = 0.0;
        const int fr0 = std::max(0, row * k - m), fr1 = std::min(fh, row * k + k + m);
        const int fc0 = std::max(0, col * k - m), fc1 = std::min(fw, col * k + k + m);
        for (int fr = fr0; fr < fr1; ++fr) {
          for (int fc = fc0; fc < fc1; ++fc) {
            const double weight = weights.empty() ? 1.0 : weights.at(0, fr, fc);
            if (!(weight > 0.0) || !std::isfinite(weight)) continue;
            float d_col = 0.0f, d_row = 0.0f;
            placement.OffsetFinePx(fc, fr, &d_col, &d_row);
            const double share = PlacedOverlap(fc + d_col, col, k) * PlacedOverlap(fr + d_row, row, k);
            const bool in_block = fr / k == row && fc / k == col;
            if (share > 0.0) {
              for (int ch = 0; ch < channels; ++ch) sum[ch] += weight * share * fine.at(ch, fr, fc);
              total += weight * share;
            }
            if (in_block) {
              for (int ch = 0; ch < channels; ++ch) own[ch] += weight * fine.at(ch, fr, fc);
              own_total += weight;
            }
          }
        }
        for (int ch = 0; ch < channels; ++ch) {
          const double value = total > 0.0 ? sum[ch] / total : own_total > 0.0 ? own[ch] / own_total : 0.0;
          out.at(ch, row, col) = static_cast<float>(value);
        }
      }
    }
  });
  return out;
}

}  // namespace u3mscan
