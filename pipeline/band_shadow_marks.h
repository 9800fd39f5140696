#pragma once
// The cast-shadow marks of a side's bands, kept per pixel and light (1 bit each), so that a later
// build of the same band takes them without marching its rays again (pipeline/tiled_side.cc: the
// fit's fine pass takes the marked sweep's marks, 2 B a fine pixel for 16 lights, instead of a
// second MarkCastShadows over every fine band from the same heights).
//
// Bands are whole rows of one grid (the side's, or its finer grid); every build of a band has the
// same lights and observations. MarkCastShadows marks every observation of a light alike, so one
// bit a light holds a pixel's marks.

#include <cstdint>
#include <vector>

#include "core/stack.h"

namespace u3mscan {

class BandShadowMarks {
 public:
  BandShadowMarks() = default;
  // A grid of width x height pixels lit by `lights` lights, every mark off.
  BandShadowMarks(int width, int height, int lights);

  bool empty() const { return bits_.empty(); }

  // Takes which pixels of `band` (its rows start at row `row0` of the grid) carry kCastShadow, per
  // light. Throws std::invalid_argument when the band is not rows of the grid or has other lights.
  void Keep(const Stack& band, int row0);

  // Sets kCastShadow on `band`'s observations where the kept marks have it and clears it elsewhere,
  // as MarkCastShadows from the same heights would (flags allocated when empty). Throws like Keep.
  void Apply(int row0, Stack* band) const;

 private:
  void Check(const Stack& band, int row0) const;
  int width_ = 0, height_ = 0, lights_ = 0;
  int bytes_per_pixel_ = 0;  // ceil(lights / 8)
  std::vector<std::uint8_t> bits_;
};

}  // namespace u3mscan
