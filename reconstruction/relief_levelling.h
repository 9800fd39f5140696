#pragma once
// Levelling a reconstructed relief: the sample's own low-order shape (a tilt, a bowl or a saddle
// across the whole map) taken out of the height and normal maps, so that they carry the
// material's relief alone.
//
// Why: a U3M material is a texture that tiles, so its displacement has no tilt or curvature over
// the sample. A real sample on the scanner bed sags or curls a little, and photometric stereo
// adds a bowl of its own: where the fitted model leaves part of a view-dependent lobe unexplained,
// the normals lean toward the camera by an angle that grows with the distance from the view's
// centre (plain weave, camera at 3x the maps' dpi: 0.3 deg at 8 mm, integrating to a 35 um bowl,
// 6.5 % of the relief's range; docs/reconstruction.md, "Levelling"). Both are smooth over the map
// and integrate into the height's longest wavelengths, which no local method can tell apart from
// the sample's shape. What a polynomial of order <= 2 over the whole map explains is removed.
//
// Frames and units (docs/capture-format.md): columns grow with +x, rows grow with -y, +z toward
// the camera; heights in mm, the pitch in mm per pixel from the height map.
//
// The normals, when given, are rotated by the removed tilt (the plane's part, a rigid pose of the
// sample) and not by the bowl. `process` and `reconstruct` give them only with --level-normals: a
// fabric whose facets slope more one way (knit) has normals with a mean slope of their own, and
// the height's tilt is then their integral, not a pose (docs/process.md, "Levelling"). Not by
// the bowl: the bowl is the integral of the steep yarn flanks' slope errors, not a lean of every
// normal. Measured on plain at 3x: the map's mean slope error leaned 0.29 deg at the edges, but
// rotating every normal by the bowl made the normal map worse (1.351 -> 1.364 deg mean), where the
// levelled height came from 7.6 % to 1.6 % of the range.

#include <array>
#include <string>

#include "core/image.h"

namespace u3mscan::reconstruction {

// kNone keeps the maps; kPlane removes a tilt (order 1); kQuadratic a tilt and a bowl or saddle
// (order 2: 1, x, y, x^2, xy, y^2).
enum class Levelling { kNone, kPlane, kQuadratic };

// "none" / "plane" / "quadratic"; ParseLevelling throws std::invalid_argument for another name.
std::string LevellingName(Levelling levelling);
Levelling ParseLevelling(const std::string& name);

struct LevellingResult {
  // The removed surface z = sum_i c_i b_i(u, v), u and v the pixel centre's offset from the map's
  // centre in units of the map's half width and half height (so -1..1), b = 1, u, v, u^2, uv, v^2;
  // mm. Terms above the order asked for are 0.
  std::array<double, 6> coefficients_mm{};
  double peak_to_valley_mm = 0.0;   // of the removed surface over the weighted pixels, constant left out
  double max_tilt_deg = 0.0;        // the largest slope of the removed surface over the map
  double weighted_pixels = 0.0;     // the weights' sum the fit used (0: nothing was removed)
};

// Fits the surface by weighted least squares to `height_mm` (1 channel) and subtracts it, keeping
// the weighted mean height; rotates each unit normal of `normal` (3 channels, same size; may be
// null) by the surface's tilt (its linear terms). `weight` (1 channel, same size, >= 0; empty = all 1)
// leaves out holes and pixels off the sample (alpha). Non-finite heights weigh 0 and are kept as
// they are. kNone, or fewer weighted pixels than the order needs, changes nothing. Throws
// std::invalid_argument on mismatched sizes.
LevellingResult LevelRelief(Levelling levelling, Image* height_mm, Image* normal, const Image& weight = Image());

}  // namespace u3mscan::reconstruction
