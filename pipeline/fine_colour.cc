#include "pipeline/fine_colour.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace u3mscan {

FineColourAverage::FineColourAverage(int maps_width, int maps_height, int k)
    : width_(maps_width), height_(maps_height), k_(k) {
  if (maps_width < 0 || maps_height < 0 || k < 1) throw std::invalid_argument("FineColourAverage: bad grid or factor");
  const std::size_t pixels = static_cast<std::size_t>(maps_width) * static_cast<std::size_t>(maps_height);
  sum_.assign(3 * pixels, 0.0f);
  weight_.assign(pixels, 0.0f);
}

void FineColourAverage::Add(const Image& base_color, const Image& cluster_id, int fine_row0, const Image& weights,
                            const PlanPlacement& placement) {
  const int rows = base_color.height();
  if (base_color.channels() != 3 || cluster_id.channels() != 1 || base_color.width() != width_ * k_ ||
      cluster_id.width() != base_color.width() || cluster_id.height() != rows || fine_row0 < 0 ||
      fine_row0 + rows > height_ * k_ ||
      (!weights.empty() && (weights.channels() != 1 || weights.width() != base_color.width() || weights.height() != rows))) {
    throw std::invalid_argument("FineColourAverage::Add: rows " + std::to_string(fine_row0) + " + " +
                                std::to_string(rows) + " of 3-channel colour, 1-channel cluster ids and weights, " +
                                std::to_string(width_ * k_) + " wide, must lie on the fine grid (" +
                                std::to_string(width_ * k_) + " x " + std::to_string(height_ * k_) + ")");
  }
  if (placement.enabled() &&
      (placement.k() != k_ || placement.width() != width_ * k_ || placement.height() != height_ * k_)) {
    throw std::invalid_argument("FineColourAverage::Add: the placement was made for another grid or factor");
  }
  for (int r = 0; r < rows; ++r) {
    const std::size_t map_row = static_cast<std::size_t>((fine_row0 + r) / k_) * static_cast<std::size_t>(width_);
    for (int c = 0; c < base_color.width(); ++c) {
      if (!(cluster_id.at(0, r, c) >= 0.0f)) continue;
      const float red = base_color.at(0, r, c), green = base_color.at(1, r, c), blue = base_color.at(2, r, c);
      if (!std::isfinite(red) || !std::isfinite(green) || !std::isfinite(blue)) continue;
      const float weight = weights.empty() ? 1.0f : weights.at(0, r, c);
      if (!(weight > 0.0f) || !std::isfinite(weight)) continue;
      if (placement.enabled()) {
        AddPlaced(c, fine_row0 + r, weight, red, green, blue, placement);
        continue;
      }
      const std::size_t i = map_row + static_cast<std::size_t>(c / k_);
      sum_[3 * i] += weight * red;
      sum_[3 * i + 1] += weight * green;
      sum_[3 * i + 2] += weight * blue;
      weight_[i] += weight;
    }
  }
}

void FineColourAverage::AddPlaced(int fine_col, int fine_row, float weight, float red, float green, float blue,
                                  const PlanPlacement& placement) {
  float d_col = 0.0f, d_row = 0.0f;
  placement.OffsetFinePx(fine_col, fine_row, &d_col, &d_row);
  const double left = fine_col + d_col, top = fine_row + d_row;
  // The moved square spans at most two map pixels along each axis.
  const int col0 = static_cast<int>(std::floor(left / k_)), row0 = static_cast<int>(std::floor(top / k_));
  for (int row = std::max(0, row0); row <= std::min(height_ - 1, row0 + 1); ++row) {
    const double along_rows = PlacedOverlap(top, row, k_);
    if (along_rows <= 0.0) continue;
    for (int col = std::max(0, col0); col <= std::min(width_ - 1, col0 + 1); ++col) {
      const double share = along_rows * PlacedOverlap(left, col, k_);
      if (share <= 0.0) continue;
      const std::size_t i = static_cast<std::size_t>(row) * static_cast<std::size_t>(width_) + static_cast<std::size_t>(col);
      const float w = static_cast<float>(weight * share);
      sum_[3 * i] += w * red;
      sum_[3 * i + 1] += w * green;
      sum_[3 * i + 2] += w * blue;
      weight_[i] += w;
    }
  }
}

long long FineColourAverage::ApplyTo(const Image& maps_cluster_id, Image* maps_base_color) const {
  if (maps_base_color->channels() != 3 || maps_base_color->width() != width_ || maps_base_color->height() != height_ ||
      maps_cluster_id.channels() != 1 || maps_cluster_id.width() != width_ || maps_cluster_id.height() != height_) {
    throw std::invalid_argument("FineColourAverage::ApplyTo: base colour (3 channels) and cluster ids (1) must be " +
                                std::to_string(width_) + " x " + std::to_string(height_));
  }
  long long set = 0;
  for (int r = 0; r < height_; ++r) {
    for (int c = 0; c < width_; ++c) {
      const std::size_t i = static_cast<std::size_t>(r) * static_cast<std::size_t>(width_) + static_cast<std::size_t>(c);
      if (!(weight_[i] > 0.0f) || !(maps_cluster_id.at(0, r, c) >= 0.0f)) continue;
      for (int ch = 0; ch < 3; ++ch) maps_base_color->at(ch, r, c) = sum_[3 * i + ch] / weight_[i];
      ++set;
    }
  }
  return set;
}

}  // namespace u3mscan
