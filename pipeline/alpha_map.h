#pragma once
// Alpha from a backlight frame: where light from the light table behind the sample passes through
// holes and open weave (capture contract, role `backlight`).

#include <cstdint>
#include <string>
#include <vector>

#include "core/image.h"

namespace u3mscan {

struct AlphaEstimate {
  Image alpha;              // 1 channel 0..1 on the grid; EMPTY when the sample shows no holes
  double fabric_level = 0;  // mean transmitted luminance of the fabric class
  double open_level = 0;    // mean transmitted luminance of the open (hole) class
  double hole_fraction = 0; // fraction of the grid that is open (alpha < 0.5)
  std::string note;         // why there is no alpha map, when there is none
};

// `transmitted`: the backlight frame on the metric grid (1 or 3 channels, linear); `flags`: grid
// ObservationFlag bits (out-of-view pixels are ignored). The frame is split into fabric and open
// classes by Otsu's threshold on luminance; holes exist only when the open class is at least
// kMinContrast times brighter and covers at least kMinHoleFraction of the grid. The ramp between
// the classes (alpha = 1 below 25 %, 0 above 75 % of the way from fabric to open level) keeps the
// estimate robust to the light table's falloff and the lens' vignetting (up to about 25 %).
AlphaEstimate AlphaFromBacklight(const Image& transmitted, const std::vector<std::uint8_t>& flags);

inline constexpr double kMinContrast = 4.0;
inline constexpr double kMinHoleFraction = 5e-4;

}  // namespace u3mscan
