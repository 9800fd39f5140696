#pragma once
// Which truth pixels an output pixel of `u3mscan evaluate` is compared with, and with what weight.
//
// A finished map pixel holds the fabric averaged over its footprint (docs/synthetic-scanner.md,
// "Pixel area"), and so does a truth pixel over its own. Two cases, by the pitches (both grids in
// world mm, pixel centres at x0 + (col + 0.5) p, y1 - (row + 0.5) p):
// - output at least as fine as the truth: the truth is interpolated bilinearly at the output pixel
//   centre (4 taps);
// - output coarser than the truth (a camera finer than the finished maps, e.g. a 600 dpi capture
//   processed at 300 dpi): the truth is averaged over the output pixel's footprint, each truth pixel
//   weighted by the area it shares with it. Point-sampling the truth there would compare a map
//   pixel with one truth pixel of its s x s.

#include <vector>

#include "bench/truth_maps.h"
#include "core/image.h"

namespace u3mscan::bench {

struct TruthTap {
  int col = 0, row = 0;  // truth pixel
  float weight = 0.0f;   // weights of one output pixel sum to 1
};

class TruthFootprint {
 public:
  // Output grid: left and top edges (mm) and pitch (mm, > 0).
  TruthFootprint(const TruthMaps& truth, double x0_mm, double y1_mm, double pitch_mm);

  // True when the output is coarser than the truth (footprint averages), false for bilinear taps.
  bool averages_footprints() const { return area_; }

  // The taps of output pixel (col, row), replacing `taps` (capacity is kept: no allocation per
  // pixel once it has grown). False when the pixel is not compared: its footprint (or its bilinear
  // neighbours) leaves the truth grid or touches a truth pixel that is not fabric (alpha < 0.5).
  bool Gather(int col, int row, std::vector<TruthTap>* taps) const;

 private:
  const TruthMaps& truth_;
  double x0_mm_, y1_mm_, pitch_mm_;
  bool area_ = false;
};

// Sum of weight * image(channel) over the taps.
float TapMean(const Image& image, int channel, const std::vector<TruthTap>& taps);

}  // namespace u3mscan::bench
