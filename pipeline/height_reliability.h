#pragma once
// Whether the reconstruction's own evidence lets the height (U3M displacement) be trusted
// (docs/fitting.md, "Reliable or not"; issue 8: "errors bounded or the affected parameters flagged").
//
// The height integrates the normals; where photometric stereo could not solve a pixel's normal (fewer
// than 3 usable lights, an ill-conditioned light system, low confidence) it regularised the normal
// toward its neighbours, i.e. guessed the slope. When guessed slopes cover a large share of the
// sample, or the mean confidence is low, the integrated height range can be off by a factor (one usable
// light per pixel: 0.14-0.21 mm for 0.10 mm). The displacement is then written, with the flag.

#include <string>

#include "reconstruction/photometric_stereo.h"

namespace u3mscan {

struct HeightReliabilityOptions {
  // Share of the side's pixels whose normal photometric stereo regularised, above which the height is
  // flagged (single-light rig: 42 %; every well-lit test capture: below 2 %; woven holes preset: 21 %).
  double max_regularised_share = 0.25;
  // Mean photometric-stereo confidence below which the height is flagged.
  double min_mean_confidence = 0.2;
};

// Empty when nothing flags the height; else the reason, with the figures that flag it.
std::string HeightUnreliableReason(const reconstruction::PhotometricStereoResult& photometric_stereo,
                                   const HeightReliabilityOptions& options = {});

}  // namespace u3mscan
