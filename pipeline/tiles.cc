#include "pipeline/tiles.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace u3mscan {

TilePlan PlanTiles(const MetricGrid& grid, int observations, bool flats, double budget_bytes, int fine_factor) {
  TilePlan plan;
  const int k = std::max(1, fine_factor);
  plan.fine_factor = k;
  const double pixels = static_cast<double>(grid.width) * grid.height;
  const double per_observation = 12.0 + 1.0 + (flats ? 4.0 : 0.0);
  plan.bytes_per_pixel = observations * per_observation + kWorkingBytesPerPixel;
  const double maps_stack_bytes = plan.bytes_per_pixel * pixels;
  plan.whole_stack_bytes = maps_stack_bytes * k * k;
  plan.band_rows = grid.height;
  if (!(budget_bytes > 0.0) || plan.whole_stack_bytes <= budget_bytes || grid.height < 2) return plan;
  const double row_bytes = plan.bytes_per_pixel * grid.width * k * k;  // one row of `grid`, k rows of the fine grid
  plan.band_rows = std::clamp(static_cast<int>(budget_bytes / row_bytes), 1, grid.height);
  plan.bands = (grid.height + plan.band_rows - 1) / plan.band_rows;
  if (plan.bands == 1) return plan;
  // Even bands: the same number of rows in each (the budget is an upper bound).
  plan.band_rows = (grid.height + plan.bands - 1) / plan.bands;
  const double sample_budget = kSampleShareOfBudget * budget_bytes;
  int step = std::max(1, static_cast<int>(std::ceil(std::sqrt(maps_stack_bytes / sample_budget))));
  while (step > 1 && pixels / (static_cast<double>(step) * step) < kMinSamplePixels) --step;
  plan.sample_step = step;
  return plan;
}

MetricGrid SampleGrid(const MetricGrid& grid, int step) {
  const int o = step / 2;
  MetricGrid sample;
  sample.width = std::max(0, (grid.width - o + step - 1) / step);
  sample.height = std::max(0, (grid.height - o + step - 1) / step);
  sample.pitch_mm = step * grid.pitch_mm;
  // Centre of sample pixel 0 = centre of grid pixel o: x0' + k p / 2 = x0 + (o + 1/2) p.
  sample.x0_mm = grid.x0_mm + (o + 0.5) * grid.pitch_mm - 0.5 * sample.pitch_mm;
  sample.y1_mm = grid.y1_mm - (o + 0.5) * grid.pitch_mm + 0.5 * sample.pitch_mm;
  return sample;
}

void SampleRows(const Image& band, int row0, int step, const MetricGrid& sample_grid, Image* sample) {
  if (sample->empty()) *sample = Image(sample_grid.width, sample_grid.height, band.channels(), 0.0f, sample_grid.pitch_mm);
  const int o = step / 2;
  for (int r = 0; r < band.height(); ++r) {
    const int row = row0 + r;
    if (row < o || (row - o) % step != 0) continue;
    const int i = (row - o) / step;
    if (i >= sample_grid.height) continue;
    for (int c = 0; c < band.channels(); ++c) {
      for (int j = 0; j < sample_grid.width; ++j) sample->at(c, i, j) = band.at(c, r, o + j * step);
    }
  }
}

Image SampleFineBlocks(const Image& fine, int fine_factor, int step, const MetricGrid& sample_grid) {
  const int k = fine_factor, o = step / 2;
  Image out(sample_grid.width * k, sample_grid.height * k, fine.channels(), 0.0f, sample_grid.pitch_mm / k);
  for (int c = 0; c < fine.channels(); ++c) {
    for (int i = 0; i < sample_grid.height; ++i) {
      for (int a = 0; a < k; ++a) {
        const int from_row = (o + i * step) * k + a;
        for (int j = 0; j < sample_grid.width; ++j) {
          for (int b = 0; b < k; ++b) out.at(c, i * k + a, j * k + b) = fine.at(c, from_row, (o + j * step) * k + b);
        }
      }
    }
  }
  return out;
}

}  // namespace u3mscan
