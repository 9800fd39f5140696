#include "pipeline/band_shadow_marks.h"

#include <algorithm>
#include <stdexcept>
#include <string>

namespace u3mscan {

BandShadowMarks::BandShadowMarks(int width, int height, int lights)
    : width_(width), height_(height), lights_(lights), bytes_per_pixel_((lights + 7) / 8) {
  if (width < 1 || height < 1 || lights < 1) throw std::invalid_argument("BandShadowMarks: an empty grid or no light");
  bits_.assign(static_cast<std::size_t>(width) * height * bytes_per_pixel_, 0);
}

void BandShadowMarks::Check(const Stack& band, int row0) const {
  if (empty()) throw std::invalid_argument("BandShadowMarks: no grid");
  if (band.grid.width != width_ || row0 < 0 || band.grid.height < 0 || row0 + band.grid.height > height_ ||
      static_cast<int>(band.lights.size()) != lights_) {
    throw std::invalid_argument("BandShadowMarks: the band (" + std::to_string(band.grid.width) + " x " +
                                std::to_string(band.grid.height) + " from row " + std::to_string(row0) + ", " +
                                std::to_string(band.lights.size()) + " lights) is not rows of the kept grid (" +
                                std::to_string(width_) + " x " + std::to_string(height_) + ", " +
                                std::to_string(lights_) + " lights)");
  }
  const std::size_t pixels = static_cast<std::size_t>(band.grid.width) * band.grid.height;
  for (const Observation& o : band.observations) {
    if (o.light < 0 || o.light >= lights_) throw std::invalid_argument("BandShadowMarks: an observation has no light");
    if (!o.flags.empty() && o.flags.size() != pixels) {
      throw std::invalid_argument("BandShadowMarks: an observation's flags are not one a pixel of the band");
    }
  }
}

void BandShadowMarks::Keep(const Stack& band, int row0) {
  Check(band, row0);
  const std::size_t pixels = static_cast<std::size_t>(band.grid.width) * band.grid.height;
  std::uint8_t* first = bits_.data() + static_cast<std::size_t>(row0) * width_ * bytes_per_pixel_;
  std::fill(first, first + pixels * bytes_per_pixel_, std::uint8_t{0});
  for (const Observation& o : band.observations) {
    if (o.flags.empty()) continue;
    const std::size_t byte = static_cast<std::size_t>(o.light) / 8;
    const auto bit = static_cast<std::uint8_t>(1u << (o.light % 8));
    for (std::size_t i = 0; i < pixels; ++i) {
      if (o.flags[i] & kCastShadow) first[i * bytes_per_pixel_ + byte] |= bit;
    }
  }
}

void BandShadowMarks::Apply(int row0, Stack* band) const {
  Check(*band, row0);
  const std::size_t pixels = static_cast<std::size_t>(band->grid.width) * band->grid.height;
  const std::uint8_t* first = bits_.data() + static_cast<std::size_t>(row0) * width_ * bytes_per_pixel_;
  for (Observation& o : band->observations) {
    if (o.flags.empty()) o.flags.assign(pixels, 0);
    const std::size_t byte = static_cast<std::size_t>(o.light) / 8;
    const auto bit = static_cast<std::uint8_t>(1u << (o.light % 8));
    for (std::size_t i = 0; i < pixels; ++i) {
      const bool shadow = (first[i * bytes_per_pixel_ + byte] & bit) != 0;
      o.flags[i] = static_cast<std::uint8_t>((o.flags[i] & ~kCastShadow) | (shadow ? kCastShadow : 0));
    }
  }
}

}  // namespace u3mscan
