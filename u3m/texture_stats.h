#pragma once
// The mean of a texture's final value, as a U3M `constant` must give it (docs/u3m-conventions.md):
// a reader that cannot load the texture still gets the right average.
//   scalar map:  offset + average(channels) * factor        (data map, linear)
//   colour map:  blend(mode, linear(image), factor), clamped to 0..1, mean per channel in linear RGB
//   normal map:  normalise((2v-1) with x, y times scale) per pixel, mean vector normalised
// Channel use: 1 = grey, 2 = grey + alpha (alpha ignored), 3 = RGB, 4 = RGBA (alpha ignored).

#include "core/image.h"
#include "u3m/material.h"

namespace u3mscan {

// `image` as read with PixelEncoding::kLinear.
double ScalarTextureMean(const Image& image, double factor, double offset);
// `image` as read with PixelEncoding::kSrgb (so already linear).
Rgb3 ColorTextureMean(const Image& image, BlendMode mode, const Rgb3& factor);
// `image` as read with PixelEncoding::kLinear.
Vec3 NormalTextureMean(const Image& image, double scale);

// Linear value of one colour blend (image value `i`, factor `f`), unclamped.
double Blend(BlendMode mode, double i, double f);

}  // namespace u3mscan

namespace u3mscan {

// How close a `constant` must be to its texture's mean (validation and writers): scalar values and
// colour channels within kConstantTolerance + kConstantTolerance * |mean| (8-bit quantisation and
// mode clamping stay well inside), normal components within kNormalConstantTolerance.
inline constexpr double kConstantTolerance = 0.02;
inline constexpr double kNormalConstantTolerance = 0.05;
inline bool ConstantAgrees(double constant, double mean) {
  const double limit = kConstantTolerance * (1.0 + (mean < 0 ? -mean : mean));
  const double d = constant - mean;
  return d <= limit && -d <= limit;
}

}  // namespace u3mscan
